//! Validation against Mitsuba 3: each scene of tests/data/mitsuba/ is rendered by zerovar and
//! compared per pixel with Mitsuba 3's image of the same XML file (`scalar_rgb`, the mean and
//! standard error of 32 independent renders, made by tools/mitsuba-references.py).
//!
//! Per pixel-channel, z = (ours - theirs) / sqrt(se_ours^2 + se_theirs^2) is about standard
//! normal when both renderers compute the same image. The checks are statistics of z whose
//! thresholds follow from that: the fraction of |z| > 3 (expected 0.27%, allowed 2%: Mitsuba's
//! standard error comes from 32 runs, so z has slightly heavier tails than a normal), the mean of
//! z (standard deviation 1/sqrt(N) over N pixel-channels, allowed 4 of them), and for each image
//! quadrant the difference of the summed pixel values over its standard error (allowed 4.5). Each
//! scene also checks that the same statistics reject our image scaled by 1.05, so a test that
//! passes is one that could have failed.
//!
//! With `ZEROVAR_MITSUBA_DEBUG` set, each test prints both images (green, every other pixel)
//! and the pixel-channels with the largest |z|.

use crate::common::repo;
use std::path::Path;
use zerovar::render::{Budget, RenderOptions, render};

/// A reference image: mean and per-pixel standard error, row-major RGB.
struct Reference {
    width: usize,
    height: usize,
    mean: Vec<[f32; 3]>,
    stderr: Vec<[f32; 3]>,
}

/// Reads the mean (channels R, G, B) and standard error (a layer named `stderr`, or channels
/// `stderr.R`, `stderr.G`, `stderr.B`) of a reference EXR.
fn read_reference(path: &Path) -> Reference {
    let image = exr::prelude::read_all_flat_layers_from_file(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let size = image.attributes.display_window.size;
    let (width, height) = (size.width(), size.height());
    let mut mean = vec![[f32::NAN; 3]; width * height];
    let mut stderr = mean.clone();
    for layer in &image.layer_data {
        let layer_is_error = layer.attributes.layer_name.as_ref().is_some_and(|n| n.eq("stderr"));
        for channel in &layer.channel_data.list {
            let name = channel.name.to_string();
            let (is_error, component) = match name.rsplit_once('.') {
                Some((prefix, c)) => (layer_is_error || prefix == "stderr", c.to_string()),
                None => (layer_is_error, name.clone()),
            };
            let Some(c) = ["R", "G", "B"].iter().position(|&x| x == component) else { continue };
            let target = if is_error { &mut stderr } else { &mut mean };
            for (i, v) in channel.sample_data.values_as_f32().enumerate() {
                target[i][c] = v;
            }
        }
    }
    let all = mean.iter().chain(&stderr).flatten();
    assert!(all.clone().all(|v| v.is_finite()), "{}: missing channels", path.display());
    Reference { width, height, mean, stderr }
}

/// The statistics of z of one comparison.
#[derive(Debug)]
struct Agreement {
    /// Fraction of pixel-channels with |z| > 3.
    outliers: f64,
    /// Mean z over all pixel-channels, in units of its standard deviation 1/sqrt(N) (reported,
    /// not asserted: see `passes`).
    mean_z: f64,
    /// (sum ours - sum theirs) / sqrt(sum of both variances) over the whole image.
    whole: f64,
    /// Per quadrant, (sum ours - sum theirs) / sqrt(sum of both variances).
    quadrants: [f64; 4],
}

impl Agreement {
    /// Whether the images agree. The bias check is on the image's pooled difference rather than
    /// on the mean of z: where a pixel's samples are skewed (a point light in fog), its estimated
    /// standard error grows with its estimate, so z leans to one side while the difference
    /// itself is unbiased; f-camera-in-fog shows a mean z of -11.5/sqrt(N) with a pooled
    /// difference of -0.4 standard errors.
    fn passes(&self) -> bool {
        self.outliers < 0.02
            && self.whole.abs() < 4.0
            && self.quadrants.iter().all(|q| q.abs() < 4.5)
    }
}

fn compare(ours: &[[f32; 3]], our_se: &[[f32; 3]], theirs: &Reference, scale: f32) -> Agreement {
    let (w, h) = (theirs.width, theirs.height);
    let (mut outliers, mut sum_z, mut n) = (0usize, 0.0f64, 0usize);
    let mut quad = [(0.0f64, 0.0f64); 4];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let q = usize::from(x >= w / 2) + 2 * usize::from(y >= h / 2);
            for c in 0..3 {
                let o = f64::from(ours[i][c] * scale);
                let so = f64::from(our_se[i][c] * scale);
                let t = f64::from(theirs.mean[i][c]);
                let st = f64::from(theirs.stderr[i][c]);
                let var = so * so + st * st;
                let d = o - t;
                // A pixel that neither renderer saw vary (a plain background) must agree to
                // rounding.
                let z = if var > 1e-14 {
                    d / var.sqrt()
                } else if d.abs() <= 1e-5 * t.abs().max(1.0) {
                    0.0
                } else {
                    d.signum() * 1e3
                };
                outliers += usize::from(z.abs() > 3.0);
                sum_z += z;
                n += 1;
                quad[q].0 += d;
                quad[q].1 += var;
            }
        }
    }
    let pooled = |(d, v): (f64, f64)| if v > 0.0 { d / v.sqrt() } else { 0.0 };
    let whole = pooled(quad.iter().fold((0.0, 0.0), |a, q| (a.0 + q.0, a.1 + q.1)));
    let quadrants = quad.map(pooled);
    Agreement {
        outliers: outliers as f64 / n as f64,
        mean_z: sum_z / n as f64 * (n as f64).sqrt(),
        whole,
        quadrants,
    }
}

/// Renders `tests/data/mitsuba/{name}.xml` with zerovar at `spp` and compares it with
/// `{name}.exr`.
fn validate(name: &str, spp: u32) {
    let xml = repo(&format!("tests/data/mitsuba/{name}.xml"));
    let scene = zerovar::scene::load(&xml, &[]).unwrap_or_else(|e| panic!("{e}"));
    validate_scene(name, &scene, spp);
}

/// [`validate`] for `scene`, loaded from `{name}.xml` or an edit of it.
fn validate_scene(name: &str, scene: &zerovar::scene::Scene, spp: u32) {
    let agreement = agreement(name, scene, spp);
    assert!(agreement.passes(), "{name}: zerovar disagrees with Mitsuba 3: {agreement:?}");
}

/// Asserts that `tests/data/mitsuba/{name}.xml` with `from` replaced by `to` disagrees with
/// Mitsuba's image at `spp`: the validation sees what the edit changes (`what` says it).
fn edited_disagrees(name: &str, spp: u32, from: &str, to: &str, what: &str) {
    let xml = repo(&format!("tests/data/mitsuba/{name}.xml"));
    let text = std::fs::read_to_string(&xml).unwrap();
    let edited = text.replace(from, to);
    assert_ne!(edited, text, "{name}: `{from}` is not in the scene");
    let scene = zerovar::scene::load_str(&xml, &edited, &[]).unwrap_or_else(|e| panic!("{e}"));
    let edited = agreement(name, &scene, spp);
    assert!(!edited.passes(), "{what} must disagree with Mitsuba's image: {edited:?}");
}

/// How `scene`'s render agrees with `{name}.exr`; panics when a 5% change to it would pass.
fn agreement(name: &str, scene: &zerovar::scene::Scene, spp: u32) -> Agreement {
    let theirs = read_reference(&repo(&format!("tests/data/mitsuba/{name}.exr")));
    let (w, h) = (theirs.width, theirs.height);
    let result = render(scene, &RenderOptions::unguided(Budget::Samples(spp), 11), &|_, _| true)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((result.film.width(), result.film.height()), (w as u32, h as u32), "{name}");
    let ours: Vec<[f32; 3]> = result.film.pixels().iter().map(|p| p.mean()).collect();
    let se: Vec<[f32; 3]> = result.film.pixels().iter().map(|p| p.std_error()).collect();
    let agreement = compare(&ours, &se, &theirs, 1.0);
    if std::env::var_os("ZEROVAR_MITSUBA_DEBUG").is_some() {
        for y in (0..h).step_by(2) {
            let row: Vec<String> = (0..w)
                .step_by(2)
                .map(|x| {
                    let i = y * w + x;
                    format!("{:.2}/{:.2}", ours[i][1], theirs.mean[i][1])
                })
                .collect();
            println!("{}", row.join(" "));
        }
        let mut worst: Vec<(f32, usize, usize)> = (0..w * h)
            .flat_map(|i| (0..3).map(move |c| (i, c)))
            .map(|(i, c)| {
                let v = se[i][c].powi(2) + theirs.stderr[i][c].powi(2);
                ((ours[i][c] - theirs.mean[i][c]) / v.sqrt().max(1e-9), i, c)
            })
            .collect();
        worst.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
        for &(z, i, c) in &worst[..8] {
            println!(
                "z {z:+.1} at ({}, {}) channel {c}: {} +- {} vs {} +- {}",
                i % w,
                i / w,
                ours[i][c],
                se[i][c],
                theirs.mean[i][c],
                theirs.stderr[i][c]
            );
        }
    }
    println!(
        "{name}: |z| > 3 in {:.2}% of pixel-channels, mean z {:+.2} / sqrt(N), pooled {:+.2}, \
         quadrants {:+.2?}",
        100.0 * agreement.outliers,
        agreement.mean_z,
        agreement.whole,
        agreement.quadrants
    );
    let scaled = compare(&ours, &se, &theirs, 1.05);
    println!("{name}, ours x 1.05: {scaled:?}");
    assert!(!scaled.passes(), "{name}: the comparison does not see a 5% change: {scaled:?}");
    agreement
}

#[test]
fn reference_format_reads_with_the_crate_reader() {
    let path = repo("tests/data/mitsuba/a-hg-sphere.exr");
    let (w, h, mean) = zerovar::output::read_exr(&path).unwrap();
    let r = read_reference(&path);
    assert_eq!((w, h), (r.width, r.height));
    assert!(mean == r.mean, "read_exr and the reference reader differ");
    assert!(r.stderr.iter().flatten().all(|&s| s >= 0.0));
    assert!(r.stderr.iter().flatten().any(|&s| s > 0.0));
}

#[test]
fn mitsuba_a_hg_sphere_point_and_constant() {
    validate("a-hg-sphere", 1024);
}

#[test]
fn mitsuba_b_cloud_grid_directional() {
    validate("b-cloud-directional", 1024);
}

#[test]
fn mitsuba_c_chromatic_medium_constant() {
    validate("c-chromatic-constant", 1024);
}

#[test]
fn mitsuba_d_medium_in_glass_spot() {
    validate("d-glass-spot", 1024);
}

#[test]
fn mitsuba_e_area_light_checkerboard_medium_cube() {
    validate("e-area-checker-cube", 1024);
}

#[test]
fn mitsuba_f_camera_in_fog_disk() {
    validate("f-camera-in-fog", 4096);
}

#[test]
fn mitsuba_g_envmap_sphere() {
    validate("g-envmap-sphere", 1024);
}

#[test]
fn mitsuba_h_media_in_obj_and_ply_meshes() {
    validate("h-mesh-media", 4096);
}

#[test]
fn mitsuba_i_thin_dielectric_pane() {
    validate("i-thin-pane", 1024);
}

#[test]
fn mitsuba_j_envmap_bilinear_seen_directly() {
    validate("j-envmap-bilinear", 1024);
}

/// A checkerboard on an OBJ quad with texture coordinates asymmetric in v, which Mitsuba
/// flips by default; a dielectric given by a material's name; a sensor without `fov`.
#[test]
fn mitsuba_l_obj_checker_named_ior_default_lens() {
    validate("l-obj-checker", 1024);
}

/// A thin dielectric's transmission is a null event, as in Mitsuba: no depth counted (at
/// `max_depth` 4) and next-event estimates through it.
#[test]
fn mitsuba_m_thin_dielectric_counts_no_depth() {
    validate("m-pane-depth", 4096);
}

/// Walls that name no medium keep the fog they stand in (zerovar made such walls borders
/// of vacuum, and rendered bench scenes' rooms 5-18% darker than Mitsuba).
#[test]
fn mitsuba_k_fog_room_walls_without_media() {
    validate("k-fog-room-walls", 4096);
}

/// Mitsuba's smooth `plastic`: default coating over a coloured base, and a nonlinear one with
/// a checkered base and a tinted specular reflection, in fog. The specular floor's skewed
/// samples need 4096 spp for trustworthy standard errors (docs/experiments.md).
#[test]
fn mitsuba_n_smooth_plastic_in_fog() {
    validate("n-plastic-fog", 4096);
}

/// Mitsuba's `roughplastic` (GGX and Beckmann, nonlinear) and `roughdielectric` around a medium,
/// in fog. Glossy highlights of the area light make the pixels' samples heavy-tailed: the
/// samples are many so that their standard errors are trustworthy.
#[test]
fn mitsuba_o_rough_plastic_and_glass_in_fog() {
    validate("o-rough-fog", 16384);
}

/// Mitsuba's `conductor` and `roughconductor`: named metals, given indices, a tint and a
/// two-sided rough floor, in fog.
#[test]
fn mitsuba_p_metals_in_fog() {
    validate("p-metal-fog", 16384);
}

/// Mitsuba's `bitmap` texture (an sRGB PNG), bilinear and repeated, nearest and clamped, on
/// OBJ quads with texture coordinates asymmetric in v.
#[test]
fn mitsuba_q_bitmap_textures() {
    validate("q-bitmap", 4096);
}

/// Mitsuba's `serialized` meshes: two meshes of one file (single and double precision, with
/// and without normals and texture coordinates), a medium's boundary and a textured quad.
#[test]
fn mitsuba_r_serialized_meshes() {
    validate("r-serialized", 4096);
}

/// Mitsuba's `mask`: opacity over a two-sided diffuse sphere and a plastic floor, crossed as
/// null events, in fog with a limited depth.
#[test]
fn mitsuba_s_masks_in_fog() {
    validate("s-mask-fog", 4096);
}

/// Mitsuba's default pixel filter (a Gaussian: the film names none) and `hide_emitters`, under
/// a constant sky: the light and the sky seen directly are black. The same scene with a box
/// filter disagrees with Mitsuba's image: the test sees the filter.
#[test]
fn mitsuba_t_default_gaussian_filter_and_hidden_emitters() {
    validate("t-gaussian-hidden", 1024);
    let boxed = "<rfilter type=\"box\"/></film>";
    edited_disagrees("t-gaussian-hidden", 1024, "</film>", boxed, "a box filter");
}

/// A tent filter of radius 1.5.
#[test]
fn mitsuba_u_tent_filter() {
    validate("u-tent", 1024);
}

/// The Mitchell-Netravali filter at Mitsuba's defaults: negative lobes, signed sample weights.
/// At 4096 spp: at 1024, dark pixels that only the lobes' tips reach from the light saw no
/// light at all, an estimate with no variance (see docs/experiments.md).
#[test]
fn mitsuba_w_mitchell_filter() {
    validate("w-mitchell", 4096);
}

/// A Lanczos filter of 2 lobes, cut at the image's edges.
#[test]
fn mitsuba_x_lanczos_filter() {
    validate("x-lanczos", 1024);
}

/// `blendphase` of an HG lobe and a Rayleigh one, its two phases written out of their names'
/// order (Mitsuba takes them as written), lit from behind the medium.
#[test]
fn mitsuba_v_blended_phase_function() {
    validate("v-blendphase", 1024);
}

/// Mitsuba's `cylinder`: an open checkered tube turned off its axis (its texture coordinates,
/// and its inside seen through the open end) and a thin glowing tube (area sampling of a
/// cylinder light), in fog.
#[test]
fn mitsuba_y_cylinders() {
    validate("y-cylinder", 16384);
}

/// A directional light seen from inside a fog that no shape bounds: Mitsuba places the light at
/// twice the scene's bounding radius, so it comes through that much fog (an infinite distance
/// would leave the image black but for nothing). The scene names its medium in the sensor
/// before defining it.
#[test]
fn mitsuba_z_sun_in_unbounded_fog() {
    validate("z-sun-unbounded-fog", 4096);
}

/// A camera whose `to_world` mirrors, which Mitsuba allows: the image flipped left to right
/// (the scene is lit from one side, so an unmirrored image disagrees).
#[test]
fn mitsuba_zb_mirrored_camera() {
    validate("zb-mirror-camera", 1024);
    edited_disagrees("zb-mirror-camera", 1024, "<scale x=\"-1\"/>", "", "an unmirrored image");
}

/// A `gridvolume` with `use_grid_bbox`: the grid fills the box its `.vol` header gives, moved
/// by `to_world` (the unit cube instead disagrees).
#[test]
fn mitsuba_zc_grid_bounding_box() {
    validate("zc-grid-bbox", 4096);
    let unit = "value=\"false\"";
    edited_disagrees("zc-grid-bbox", 1024, "value=\"true\"", unit, "the grid in the unit cube");
}

/// Texture coordinates of PLY meshes: as written by default (Mitsuba's PLY reader), flipped
/// in v by `flip_tex_coords` (OBJ's default instead disagrees).
#[test]
fn mitsuba_zd_ply_texture_coordinates() {
    validate("zd-ply-uv", 1024);
    let (from, flipped) = (
        "</transform>\n        <bsdf",
        "</transform><boolean name=\"flip_tex_coords\" value=\"true\"/><bsdf",
    );
    edited_disagrees("zd-ply-uv", 1024, from, flipped, "v flipped as OBJ flips it");
}

/// Anisotropic roughness on every kind of shape (sphere, disk, cube, rectangle; metal and
/// glass): each surface is brushed along its own parameterization, as in Mitsuba. The metal
/// sphere brushed the other way disagrees with Mitsuba's image: the test sees the tangents.
#[test]
fn mitsuba_ze_brushed_surfaces() {
    validate("ze-brushed", 4096);
    let brushed = |u: &str, v: &str| {
        format!("\"alpha_u\" value=\"{u}\"/>\n            <float name=\"alpha_v\" value=\"{v}\"")
    };
    let (along, across) = (brushed("0.04", "0.45"), brushed("0.45", "0.04"));
    edited_disagrees("ze-brushed", 4096, &along, &across, "the sphere brushed the other way");
}

/// Roughness and a mask's opacity read from textures: checkerboards (whose colours `eval_1`
/// reads the other way round from colour lookups), raw and sRGB-decoded grey PNGs and a
/// coloured checkerboard read by its luminance. The gold sphere's checkerboard read as colour
/// lookups read it disagrees with Mitsuba's image.
#[test]
fn mitsuba_zf_textured_roughness_and_opacity() {
    validate("zf-textured-rough", 4096);
    let (from, to) = ("\"color0\" value=\"0.03\"", "\"color0\" value=\"0.5\"");
    edited_disagrees("zf-textured-rough", 4096, from, to, "a checkerboard of one roughness");
}

/// Mitsuba's `thinlens` sensor: spheres before, at and beyond the focal plane over a checkered
/// floor, through fog; with spectrum pairs separated by spaces and emitters' `sampling_weight`
/// (Mitsuba's noise, not its image). A pinhole instead disagrees with Mitsuba's image: the test
/// sees the blur.
#[test]
fn mitsuba_zg_thin_lens() {
    validate("zg-thinlens", 4096);
    let (from, to) = (
        "value=\"0.2\"/>\n        <float name=\"focus",
        "value=\"0.001\"/>\n        <float name=\"focus",
    );
    edited_disagrees("zg-thinlens", 4096, from, to, "a pinhole");
}
