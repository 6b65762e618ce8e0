//! The library as an embedding application uses it: media supplied in code.

use crate::common::{assert_same_image, scene};
use glam::{Vec3, Vec3A};
use std::sync::Arc;
use zerovar::math::Spectrum;
use zerovar::media::{
    AlbedoField, DensityField, DensityFunction, Grid, Heterogeneous, Medium, MediumKind, VolGrid,
};
use zerovar::phase::PhaseFunction;
use zerovar::render::{Budget, RenderOptions, render};
use zerovar::transform::Transform;

const SCENE: &str = r#"
[camera]
origin = [0, 0.5, 3.5]
target = [0, 0, 0]
fov = 40
resolution = [16, 12]

[media.m]
type = "homogeneous"

[[shapes]]
type = "cube"
bsdf = { type = "null" }
interior = "m"

[[lights]]
type = "directional"
direction = [-0.3, -1, -0.5]
irradiance = 2
angular_diameter = 1

[[lights]]
type = "constant"
radiance = 0.3
"#;

/// A host density that is the grid's own trilinear lookup, with only a global bound.
#[derive(Debug)]
struct Host(Grid);

impl DensityFunction for Host {
    fn density(&self, p: Vec3A) -> f32 {
        self.0.scalar(p)
    }
    fn max_density(&self) -> f32 {
        self.0.max_value()
    }
}

fn grid() -> Grid {
    let data = (0..6 * 5 * 4).map(|i| ((i * 37 % 11) as f32 / 10.0).powi(2)).collect();
    Grid::new(VolGrid::new([6, 5, 4], 1, data).expect("a valid grid"))
}

fn medium(density: DensityField) -> Medium {
    let to_world =
        Transform::scale(Vec3::splat(2.0)).unwrap().then(&Transform::translate(Vec3::splat(-1.0)));
    let h = Heterogeneous::new(
        to_world,
        density,
        6.0,
        Spectrum::ONE,
        AlbedoField::Constant(Spectrum::splat(0.9)),
    );
    Medium {
        name: "ignored".into(),
        kind: MediumKind::Heterogeneous(Box::new(h)),
        phase: PhaseFunction::HenyeyGreenstein { g: 0.4 },
        emission: Spectrum::ZERO,
    }
}

#[test]
fn a_host_density_renders_like_the_same_grid() {
    let mut as_grid = scene(SCENE);
    as_grid.replace_medium("m", medium(DensityField::Grid(grid()))).unwrap();
    let mut as_host = scene(SCENE);
    as_host.replace_medium("m", medium(DensityField::Custom(Arc::new(Host(grid()))))).unwrap();
    assert_eq!(as_host.media()[0].name, "m");
    let a =
        render(&as_grid, &RenderOptions::unguided(Budget::Samples(512), 1), &|_, _| true).unwrap();
    let b =
        render(&as_host, &RenderOptions::unguided(Budget::Samples(512), 2), &|_, _| true).unwrap();
    assert_same_image(&a.film, &b.film, 4.5, "host density against grid");
    // The comparison can fail: a different density is told apart.
    let mut other = scene(SCENE);
    other
        .replace_medium(
            "m",
            medium(DensityField::Custom(Arc::new(Host(Grid::new(
                VolGrid::new([1, 1, 1], 1, vec![0.1]).expect("a valid grid"),
            ))))),
        )
        .unwrap();
    let c =
        render(&other, &RenderOptions::unguided(Budget::Samples(512), 3), &|_, _| true).unwrap();
    let differs =
        std::panic::catch_unwind(|| assert_same_image(&a.film, &c.film, 4.5, "different")).is_err();
    assert!(differs, "a much thinner medium rendered the same image");
    let err = as_grid.replace_medium("nope", medium(DensityField::Grid(grid()))).unwrap_err();
    assert!(err.to_string().contains("nope") && err.to_string().contains("m"), "{err}");
}

#[test]
fn cancelling_from_the_callback_returns_whole_passes() {
    let s = scene(SCENE);
    let total_spp = 4096;
    let calls = std::sync::atomic::AtomicU64::new(0);
    let start = std::time::Instant::now();
    // Cancel as soon as anything is reported: the first pass (1 spp) completes at most.
    let r = render(&s, &RenderOptions::unguided(Budget::Samples(total_spp), 1), &|_, _| {
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        false
    })
    .unwrap();
    assert!(r.cancelled);
    assert!(r.spp < total_spp, "{} spp after cancelling", r.spp);
    assert!(calls.load(std::sync::atomic::Ordering::Relaxed) >= 1);
    assert!(r.film.pixels().iter().all(|p| p.count == r.spp), "pixels hold partial passes");
    assert!(r.image.iter().flatten().all(|v| v.is_finite()));
    assert!(start.elapsed().as_secs_f64() < 5.0, "cancelling took {:?}", start.elapsed());
    // Not cancelling renders everything.
    let full = render(&s, &RenderOptions::unguided(Budget::Samples(8), 1), &|_, _| true).unwrap();
    assert!(!full.cancelled && full.spp == 8);
    // Cancelling while a field trains is an error, not a half-trained render.
    let mut guided = RenderOptions::unguided(Budget::Samples(8), 1);
    guided.guiding.components = zerovar::guided::Components::FULL;
    let err = render(&s, &guided, &|_, _| false).unwrap_err();
    assert!(matches!(err, zerovar::render::RenderError::Cancelled), "{err}");
}

#[test]
fn options_assembled_in_code_are_validated_before_any_work() {
    use std::time::Duration;
    use zerovar::render::{OptionsError, RenderError, TrainBudget, train};
    let s = scene(SCENE);
    let good = || {
        let mut o = RenderOptions::unguided(Budget::Samples(1), 1);
        o.guiding.components = zerovar::guided::Components::FULL;
        o
    };
    let cases: Vec<(RenderOptions, OptionsError)> = vec![
        (RenderOptions { budget: Budget::Samples(0), ..good() }, OptionsError::ZeroSamples),
        (RenderOptions { budget: Budget::Time(Duration::ZERO), ..good() }, OptionsError::ZeroTime),
        (RenderOptions { threads: Some(0), ..good() }, OptionsError::ZeroThreads),
        {
            let mut o = good();
            o.guiding.alpha = 1.5;
            (o, OptionsError::Alpha(1.5))
        },
        {
            let mut o = good();
            o.guiding.surface_alpha = 2.0;
            (o, OptionsError::SurfaceAlpha(2.0))
        },
        {
            let mut o = good();
            o.guiding.distance_alpha = -0.5;
            (o, OptionsError::DistanceAlpha(-0.5))
        },
        {
            let mut o = good();
            o.guiding.train = TrainBudget::Passes(21);
            (o, OptionsError::TrainPasses(21))
        },
        {
            let mut o = good();
            o.guiding.train = TrainBudget::Time(Duration::ZERO);
            (o, OptionsError::ZeroTrainTime)
        },
    ];
    for (options, expected) in cases {
        // Any work would call the callback; validation must refuse before it.
        let refuse = |_: u64, _: u64| -> bool { panic!("work started for {expected:?}") };
        let err = render(&s, &options, &refuse).unwrap_err();
        assert!(matches!(&err, RenderError::Options(e) if *e == expected), "{err}");
        let err = train(&s, &options, &refuse).unwrap_err();
        assert!(matches!(&err, RenderError::Options(e) if *e == expected), "{err}");
    }
    let mut nan = good();
    nan.guiding.alpha = f32::NAN;
    assert!(matches!(nan.validate(), Err(OptionsError::Alpha(a)) if a.is_nan()));
    let mut nan = good();
    nan.guiding.surface_alpha = f32::NAN;
    assert!(matches!(nan.validate(), Err(OptionsError::SurfaceAlpha(a)) if a.is_nan()));
    let mut nan = good();
    nan.guiding.distance_alpha = f32::NAN;
    assert!(matches!(nan.validate(), Err(OptionsError::DistanceAlpha(a)) if a.is_nan()));
    assert_eq!(good().validate(), Ok(()));
}

/// The fog sphere of `scenes/fog-sphere.toml`, assembled in code at `resolution`.
fn fog_sphere_in_code(resolution: [u32; 2]) -> zerovar::scene::SceneBuilder {
    use zerovar::scene::SceneBuilder;
    use zerovar::scene::desc::{
        BsdfDesc, CameraDesc, CheckerboardDesc, LightDesc, MediumDesc, PhaseDesc, Rgb, ShapeDesc,
        TextureDesc, TransformStep,
    };
    let camera = CameraDesc {
        near_clip: 0.01,
        far_clip: 1e4,
        ..CameraDesc::look_at(Vec3::new(0.0, 2.2, 6.5), Vec3::new(0.0, 0.9, 0.0), 40.0, resolution)
    };
    let fog = MediumDesc {
        phase: Some(PhaseDesc::hg(0.3)),
        ..MediumDesc::homogeneous(Rgb::Grey(1.5), Rgb::Grey(0.9))
    };
    let floor = BsdfDesc {
        reflectance: Some(TextureDesc::Checkerboard(CheckerboardDesc {
            kind: "checkerboard".into(),
            color0: Some(Rgb::Grey(0.6)),
            color1: Some(Rgb::Grey(0.3)),
            scale: Some([5.0, 5.0]),
        })),
        ..BsdfDesc::diffuse(Rgb::Grey(0.5))
    };
    let floor_place = vec![
        TransformStep::Rotate { axis: Vec3::X, angle: -90.0 },
        TransformStep::Scale(Rgb::Grey(5.0)),
    ];
    SceneBuilder::new(camera)
        .medium("fog", fog)
        .shape(ShapeDesc {
            interior: Some("fog".into()),
            ..ShapeDesc::sphere(Vec3::new(0.0, 1.0, 0.0), 1.0, BsdfDesc::null())
        })
        .shape(ShapeDesc::placed("rectangle", floor_place, floor))
        .light(LightDesc::point(Vec3::new(1.5, 3.2, 1.5), Rgb::Rgb([30.0, 27.0, 24.0])))
        .light(LightDesc::constant(Rgb::Grey(0.05)))
}

#[test]
fn a_scene_built_in_code_renders_exactly_as_its_file() {
    let built = fog_sphere_in_code([40, 30]).build().unwrap_or_else(|e| panic!("{e}"));
    let path = crate::common::repo("scenes/fog-sphere.toml");
    let text = std::fs::read_to_string(&path).unwrap().replace("[320, 240]", "[40, 30]");
    let loaded = zerovar::scene::load_str(&path, &text, &[]).unwrap();
    let options = RenderOptions::unguided(Budget::Samples(2), 3);
    let a = render(&built, &options, &|_, _| true).unwrap();
    let b = render(&loaded, &options, &|_, _| true).unwrap();
    assert_eq!(a.film.pixels(), b.film.pixels());
    assert!(a.image.iter().any(|p| p[0] > 0.0), "the image is not black");

    // Invalid elements are the same errors as in a file, naming the element.
    use zerovar::scene::desc::{BsdfDesc, ShapeDesc};
    let bad = fog_sphere_in_code([40, 30])
        .shape(ShapeDesc::sphere(Vec3::ZERO, -1.0, BsdfDesc::null()))
        .build()
        .unwrap_err()
        .to_string();
    assert!(bad.contains("<scene built in code>") && bad.contains("shapes[2]"), "{bad}");
    let unknown = fog_sphere_in_code([40, 30]).global_medium("smoke").build().unwrap_err();
    assert!(unknown.to_string().contains("smoke"), "{unknown}");
}

/// A `.vol` file of `channels` values per voxel over a 2x2x1 grid.
fn vol_file(channels: i32, values: &[f32]) -> Vec<u8> {
    let mut b = b"VOL\x03".to_vec();
    for i in [1i32, 2, 2, 1, channels] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    for v in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0].iter().chain(values) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}

/// An RGB extinction grid whose channels keep one proportion (as Mitsuba scenes of chromatic
/// smoke give them) renders exactly as its largest channel times that colour.
#[test]
fn a_proportional_rgb_density_is_a_density_times_a_colour() {
    let density = [0.8f32, 0.2, 0.0, 1.0];
    let colour = [0.5f32, 1.0, 0.25];
    let rgb: Vec<f32> = density.iter().flat_map(|d| colour.map(|c| d * c)).collect();
    crate::common::write("rgb-density.vol", vol_file(3, &rgb));
    crate::common::write("grey-density.vol", vol_file(1, &density));
    let a = load_grid("rgb.toml", "rgb-density.vol", "1");
    let b = load_grid("grey.toml", "grey-density.vol", "[0.5, 1.0, 0.25]");
    let options = RenderOptions::unguided(Budget::Samples(8), 4);
    let ra = render(&a, &options, &|_, _| true).unwrap();
    let rb = render(&b, &options, &|_, _| true).unwrap();
    assert_eq!(ra.image, rb.image, "the same medium either way");
}

/// A grid medium lit by a constant sky, seen from the front, with the density `file`.
fn load_grid(name: &str, file: &str, sigma_t: &str) -> zerovar::scene::Scene {
    let body = format!(
        "[camera]\norigin = [0, 0.5, 3]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [8, 6]\n\n\
         [media.m]\ntype = \"grid\"\ndensity = \"{file}\"\nsigma_t = {sigma_t}\nscale = 3\nalbedo = 0.8\n\
         transform = [{{ translate = [-0.5, -0.5, -0.5] }}]\n\n\
         [[shapes]]\ntype = \"cube\"\ntransform = [{{ scale = 0.5 }}]\nbsdf = {{ type = \"null\" }}\ninterior = \"m\"\n\n\
         [[lights]]\ntype = \"constant\"\nradiance = 1\n"
    );
    let path = crate::common::write(name, &body);
    zerovar::scene::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// An RGB extinction grid whose channels vary apart is tracked spectrally: each channel of its
/// image agrees with the image of a grey grid holding that channel alone (a different tracker
/// on a different scene), to within 4 standard errors of 0.3% or less.
#[test]
fn an_rgb_density_renders_each_channel_as_its_own_grey_grid() {
    let rgb = [0.8f32, 0.1, 2.0, 0.2, 1.5, 0.4, 0.0, 0.3, 0.9, 1.0, 0.0, 0.6];
    crate::common::write("apart.vol", vol_file(3, &rgb));
    let scene = load_grid("apart.toml", "apart.vol", "1");
    assert!(scene.media()[0].is_chromatic(), "an RGB grid is chromatic");
    // The image mean of channel `c` over `seeds` renders: its mean and standard error.
    let mean = |scene: &zerovar::scene::Scene, c: usize, seeds: u64| {
        let means: Vec<f64> = (0..seeds)
            .map(|seed| {
                let mut options = RenderOptions::unguided(Budget::Samples(256), 2);
                options.seed = seed;
                let r = render(scene, &options, &|_, _| true).unwrap();
                r.image.iter().map(|p| f64::from(p[c])).sum::<f64>() / r.image.len() as f64
            })
            .collect();
        let m = means.iter().sum::<f64>() / seeds as f64;
        let var = means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (seeds - 1) as f64;
        (m, (var / seeds as f64).sqrt())
    };
    for c in 0..3 {
        let grey: Vec<f32> = rgb.iter().skip(c).step_by(3).copied().collect();
        let file = format!("apart-{c}.vol");
        crate::common::write(&file, vol_file(1, &grey));
        let alone = load_grid(&format!("apart-{c}.toml"), &file, "1");
        let (a, sa) = mean(&scene, c, 8);
        let (b, sb) = mean(&alone, c, 8);
        let se = (sa * sa + sb * sb).sqrt();
        assert!(se < 3e-3 * b, "channel {c}: standard error {se} too large to see a 1% bias");
        assert!((a - b).abs() < 4.0 * se, "channel {c}: {a} vs {b} (standard error {se})");
    }
}
