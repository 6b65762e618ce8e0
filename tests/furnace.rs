//! White furnace: a sphere of non-absorbing medium under a uniform environment of radiance 1
//! must render exactly 1 in expectation, in every channel, whatever its density, phase
//! function or colour; with absorption it must render measurably less.

use crate::common::{estimate_region, scene};
use glam::Vec2;

const PATHS: u64 = 20_000;
/// Each check is a z-test; with fixed seeds a false alarm at 4.5 sigma has odds ~1e-5.
const Z: f64 = 4.5;

fn furnace(medium: &str) -> String {
    format!(
        r#"
[camera]
origin = [0, 0, 4]
target = [0, 0, 0]
fov = 20
resolution = [8, 8]

[media.m]
{medium}

[[shapes]]
type = "sphere"
radius = 1
bsdf = {{ type = "null" }}
interior = "m"

[[lights]]
type = "constant"
radiance = 1
"#
    )
}

fn check(medium: &str, seed: u64) -> [zerovar_testkit::MeanEstimate; 3] {
    let s = scene(&furnace(medium));
    estimate_region(&s, seed, PATHS, (Vec2::ZERO, Vec2::splat(8.0)))
}

fn assert_white(medium: &str, seed: u64) {
    for (c, e) in check(medium, seed).iter().enumerate() {
        e.assert_matches(1.0, Z, &format!("furnace channel {c} of\n{medium}\n"));
    }
}

#[test]
fn homogeneous_grey_all_densities_and_phase_functions() {
    for (i, density) in [0.05, 1.0, 8.0].into_iter().enumerate() {
        for (j, g) in [-0.9, 0.0, 0.5, 0.9].into_iter().enumerate() {
            let medium = format!(
                "type = \"homogeneous\"\nsigma_t = {density}\nalbedo = 1\nphase = {{ type = \"hg\", g = {g} }}"
            );
            assert_white(&medium, (i * 10 + j) as u64);
        }
    }
}

#[test]
fn homogeneous_chromatic() {
    assert_white(
        "type = \"homogeneous\"\nsigma_t = [0.3, 2.0, 9.0]\nalbedo = 1\nphase = { type = \"hg\", g = 0.6 }",
        1,
    );
}

#[test]
fn heterogeneous_grey_and_chromatic() {
    let cloud = "type = \"noise\"\nalbedo = 1\nscale = 12\ntransform = [{ translate = [-0.5, -0.5, -0.5] }, { scale = 1.4 }]";
    assert_white(cloud, 2);
    assert_white(
        &format!("{cloud}\nsigma_t = [0.2, 1.0, 2.5]\nphase = {{ type = \"hg\", g = -0.4 }}"),
        3,
    );
}

#[test]
fn absorption_renders_measurably_less() {
    let e = check("type = \"homogeneous\"\nsigma_t = 3\nalbedo = 0.9", 4);
    for (c, e) in e.iter().enumerate() {
        assert!(
            e.mean + 5.0 * e.std_error() < 0.95,
            "channel {c}: {} +- {}",
            e.mean,
            e.std_error()
        );
    }
    // One absorbing channel darkens only that channel.
    let e = check("type = \"homogeneous\"\nsigma_t = 3\nalbedo = [1, 1, 0.5]", 5);
    e[0].assert_matches(1.0, Z, "non-absorbing red");
    assert!(e[2].mean + 5.0 * e[2].std_error() < 0.9, "absorbing blue: {}", e[2].mean);
}
