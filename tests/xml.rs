//! Mitsuba 3 XML scenes: each example renders exactly as its TOML twin, transforms follow
//! Mitsuba's order, `<default>`, `-D`, `<include>` and `<ref>` work, and bad input is an error
//! at the right line and column that says what to do.

use crate::common::{repo, temp_dir, write};
use glam::{Vec2, Vec3A};
use zerovar::render::{Budget, RenderOptions, render};
use zerovar::scene::{Scene, SceneError, load_str};

fn defines(d: &[(&str, &str)]) -> Vec<(String, String)> {
    d.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
}

/// A repository scene with its text edited (to shrink the image), loaded as if in place.
fn edited(path: &str, edits: &[(&str, &str)], d: &[(&str, &str)]) -> Scene {
    let path = repo(path);
    let mut text = std::fs::read_to_string(&path).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{from} not in {}", path.display());
        text = text.replace(from, to);
    }
    load_str(&path, &text, &defines(d)).unwrap_or_else(|e| panic!("{e}"))
}

fn image(scene: &Scene, seed: u64) -> Vec<[f32; 3]> {
    render(scene, &RenderOptions::unguided(Budget::Samples(2), seed), &|_, _| true).unwrap().image
}

/// An XML scene from text, written to the temporary directory as `name`.
fn xml(name: &str, text: &str, d: &[(&str, &str)]) -> Result<Scene, SceneError> {
    let path = write(name, text);
    zerovar::scene::load(&path, &defines(d))
}

const SMALL_XML: [(&str, &str); 2] = [
    ("name=\"width\" value=\"320\"", "name=\"width\" value=\"40\""),
    ("name=\"height\" value=\"240\"", "name=\"height\" value=\"30\""),
];

#[test]
fn fog_sphere_xml_renders_exactly_as_the_toml() {
    let toml = [("resolution = [320, 240]", "resolution = [40, 30]")];
    let a = edited("scenes/fog-sphere.toml", &toml, &[]);
    let b = edited("scenes/xml/fog-sphere.xml", &SMALL_XML, &[]);
    assert_eq!(b.settings().spp, 256);
    assert!(image(&a, 5) == image(&b, 5), "fog sphere: XML and TOML images differ");
    // -D overrides a <default> as it overrides a [defaults] entry.
    let a = edited("scenes/fog-sphere.toml", &toml, &[("density", "4"), ("spp", "3")]);
    let b = edited("scenes/xml/fog-sphere.xml", &SMALL_XML, &[("density", "4"), ("spp", "3")]);
    assert_eq!(b.settings().spp, 3);
    assert_eq!(b.media()[0].majorant().to_array(), [4.0; 3]);
    assert!(image(&a, 6) == image(&b, 6), "fog sphere with -D: XML and TOML images differ");
}

/// The bench scenes' XML twins (which tools/mitsuba-bench.py renders with Mitsuba 3) are the
/// same scenes as the TOML files bench/run.sh renders with zerovar: the same settings and,
/// with the same seed, the same image bit for bit.
#[test]
fn bench_xml_twins_render_exactly_as_the_toml() {
    for name in ["backlit-cloud", "chromatic-slab", "easy", "light-shaft", "occluded-light"] {
        let a = edited(&format!("scenes/bench/{name}.toml"), &[], &[]);
        let b = edited(&format!("scenes/bench/{name}.xml"), &[], &[]);
        assert_eq!(format!("{:?}", a.settings()), format!("{:?}", b.settings()), "{name}");
        assert_eq!(a.lights().len(), b.lights().len(), "{name}");
        assert!(image(&a, 7) == image(&b, 7), "{name}: XML and TOML images differ");
    }
}

#[test]
fn cloud_xml_renders_exactly_as_the_toml_with_a_delta_sun() {
    let toml =
        [("resolution = [320, 200]", "resolution = [40, 25]"), ("angular_diameter = 0.53", "")];
    let a = edited("scenes/cloud.toml", &toml, &[]);
    // The camera comes from an included file; shrink it through a copy of the scene that
    // includes an edited camera.
    let camera = std::fs::read_to_string(repo("scenes/xml/cloud-camera.xml")).unwrap();
    let camera =
        camera.replace("value=\"320\"", "value=\"40\"").replace("value=\"200\"", "value=\"25\"");
    let dir = temp_dir().join("cloud");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("cloud-camera.xml"), camera).unwrap();
    let scene = std::fs::read_to_string(repo("scenes/xml/cloud.xml")).unwrap();
    let vol = repo("scenes/data/cloud.vol");
    let scene = scene.replace("../data/cloud.vol", vol.to_str().unwrap());
    let b = load_str(&dir.join("cloud.xml"), &scene, &[]).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(b.settings().max_depth, Some(64));
    assert!(image(&a, 7) == image(&b, 7), "cloud: XML and TOML images differ");
}

const CAMERA: &str = r#"
    <sensor type="perspective">
        <float name="fov" value="50"/>
        <string name="fov_axis" value="larger"/>
        <transform name="to_world">TO_WORLD</transform>
        <film type="hdrfilm">
            <integer name="width" value="30"/>
            <integer name="height" value="40"/>
            <rfilter type="box"/>
        </film>
    </sensor>"#;

fn with_camera(to_world: &str, body: &str) -> String {
    format!(
        "<scene version=\"3.0.0\">{}\n<integrator type=\"volpath\"/>\n{body}\n</scene>\n",
        CAMERA.replace("TO_WORLD", to_world)
    )
}

#[test]
fn transforms_follow_mitsuba_order() {
    // Translate, then rotate by 90 degrees about z, then scale by 2: the sphere centred at
    // (1, 0, 0) with radius 0.5 lands centred at (0, 2, 0) with radius 1.
    let shape = r#"<shape type="sphere">
        <point name="center" value="1, 0, 0"/>
        <float name="radius" value="0.5"/>
        <transform name="to_world">
            <rotate z="1" angle="90"/>
            <scale value="2"/>
        </transform>
    </shape>"#;
    let lookat = r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#;
    let s = xml("order.xml", &with_camera(lookat, shape), &[]).unwrap();
    let b = s.bounds();
    assert!((b.min - Vec3A::new(-1.0, 1.0, -1.0)).abs().max_element() < 1e-5, "{b:?}");
    assert!((b.max - Vec3A::new(1.0, 3.0, 1.0)).abs().max_element() < 1e-5, "{b:?}");

    // The same camera as a rotate/translate chain and as a matrix; a rectangle placed by
    // scale, rotate, translate as in the TOML format.
    let chain = r#"<rotate y="1" angle="180"/><translate z="5"/>"#;
    let matrix = r#"<matrix value="-1 0 0 0  0 1 0 0  0 0 -1 5  0 0 0 1"/>"#;
    let rect = r#"<shape type="rectangle"><transform name="to_world">
        <scale x="2" y="1" z="1"/><rotate x="1" angle="-90"/><translate value="0, -1, 0"/>
    </transform></shape>"#;
    let toml = r#"
[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
fov = 50
fov_axis = "y"
resolution = [30, 40]

[[shapes]]
type = "rectangle"
transform = [{ scale = [2, 1, 1] }, { rotate = { axis = [1, 0, 0], angle = -90 } }, { translate = [0, -1, 0] }]
"#;
    let t = crate::common::scene(toml);
    for to_world in [lookat, chain, matrix] {
        let s = xml("camera.xml", &with_camera(to_world, rect), &[]).unwrap();
        for film in [Vec2::new(0.0, 0.0), Vec2::new(15.0, 20.0), Vec2::new(30.0, 7.0)] {
            let (a, b) = (t.camera().ray(film), s.camera().ray(film));
            let eyes = (t.camera().origin(), s.camera().origin());
            assert!((eyes.0 - eyes.1).abs().max_element() < 1e-5, "{to_world}");
            assert!((a.direction - b.direction).abs().max_element() < 1e-5, "{to_world}");
        }
        assert_eq!(s.bounds().min, t.bounds().min);
        assert_eq!(s.bounds().max, t.bounds().max);
    }
}

#[test]
fn lights_match_the_toml_format() {
    let body = r#"
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/></transform>
        <bsdf type="twosided"><bsdf type="diffuse"><spectrum name="reflectance" value="400:0.1, 500:0.5, 600:0.8, 700:0.9"/></bsdf></bsdf>
    </shape>
    <shape type="disk">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="2"/></emitter>
    </shape>
    <emitter type="spot">
        <transform name="to_world"><lookat origin="1, 3, 0" target="0, 0, 0" up="0, 1, 0"/></transform>
        <float name="intensity" value="20"/>
        <float name="cutoff_angle" value="30"/>
    </emitter>
    <emitter type="directional">
        <transform name="to_world"><lookat origin="0, 0, 0" target="-1, -2, -1" up="0, 1, 0"/></transform>
        <spectrum name="irradiance" value="0.5"/>
    </emitter>
    <emitter type="envmap">
        <string name="filename" value="sky.exr"/>
        <float name="scale" value="2"/>
        <transform name="to_world"><rotate y="1" angle="90"/></transform>
    </emitter>"#;
    let toml = r#"
[camera]
origin = [0, 3, 6]
target = [0, 0, 0]
fov = 40
resolution = [24, 18]
# Mitsuba's filter where the film names none.
filter = { type = "gaussian", stddev = 0.5 }

[[shapes]]
type = "rectangle"
transform = [{ rotate = { axis = [1, 0, 0], angle = -90 } }, { scale = 3 }]
# The spectrum's colour in Mitsuba 3.9.1 scalar_rgb (`mi.traverse`).
bsdf = { type = "diffuse", reflectance = [0.87801546, 0.6357789, 0.27034214], two_sided = true }

[[shapes]]
type = "disk"
transform = [{ rotate = { axis = [1, 0, 0], angle = 90 } }, { translate = [0, 2, 0] }]
emitter = { radiance = 2 }
# Mitsuba's emitting shape without a <bsdf> reflects nothing.
bsdf = { type = "diffuse", reflectance = 0 }

[[lights]]
type = "spot"
position = [1, 3, 0]
target = [0, 0, 0]
intensity = 20
cutoff_angle = 30

# A one-value <spectrum> in an emitter is equal-energy light: 0.5 x xyz_to_srgb(1, 1, 1).
[[lights]]
type = "directional"
direction = [-1, -2, -1]
irradiance = [0.6023970, 0.4741455, 0.4544580]

[[lights]]
type = "envmap"
filename = "sky.exr"
scale = 2
transform = [{ rotate = { axis = [0, 1, 0], angle = 90 } }]
"#;
    let camera = r#"<sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 3, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="18"/></film>
    </sensor>"#;
    let sky: Vec<[f32; 3]> =
        (0..32).map(|i| [0.1 * (i % 8) as f32, 0.05 * (i / 8) as f32, 0.3]).collect();
    let meta =
        zerovar::output::ImageMetadata { spp: 1, seconds: 0.0, seed: 0, scene: String::new() };
    zerovar::output::write_exr(&temp_dir().join("sky.exr"), 8, 4, &sky, &meta).unwrap();
    let text = format!("<scene version=\"3.0.0\">{camera}{body}</scene>");
    let a = crate::common::scene(toml);
    let b = xml("lights.xml", &text, &[]).unwrap();
    let (ia, ib) = (image(&a, 1), image(&b, 1));
    for (p, q) in ia.iter().zip(&ib) {
        for c in 0..3 {
            assert!((p[c] - q[c]).abs() <= 1e-4 * (1.0 + p[c].abs()), "{p:?} vs {q:?}");
        }
    }
}

const REFS: &str = r#"<scene version="3.0.0">
    <default name="r" value="0.5"/>
    <medium type="homogeneous" id="haze">
        <rgb name="sigma_a" value="0.1, 0.2, 0.3"/>
        <rgb name="sigma_s" value="0.3"/>
    </medium>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
        <ref id="haze"/>
    </sensor>
    <integrator type="moment"><integrator type="volpathmis"><integer name="max_depth" value="8"/></integrator></integrator>
    <bsdf type="dielectric" id="glass"><float name="int_ior" value="1.33"/></bsdf>
    <shape type="sphere">
        <float name="radius" value="$r"/>
        <ref id="glass"/>
        <ref name="exterior" id="haze"/>
    </shape>
    <shape type="sphere">
        <point name="center" x="2"/>
        <ref id="glass"/>
        <ref name="exterior" id="haze"/>
    </shape>
</scene>
"#;

/// As in Mitsuba, a `<ref>` may name an object defined later in the file (a sensor that
/// names the medium it sits in, written before it): the same scene as with the objects in
/// order, a medium referenced twice still one medium; a cycle, an unknown id and an endless
/// chain of references are errors that say where.
#[test]
fn references_may_come_before_their_objects() {
    let medium = r#"<medium type="homogeneous" id="haze">
        <rgb name="sigma_a" value="0.1, 0.2, 0.3"/>
        <rgb name="sigma_s" value="0.3"/>
    </medium>"#;
    let glass = r#"<bsdf type="dielectric" id="glass"><float name="int_ior" value="1.33"/></bsdf>"#;
    let ordered = REFS.replace(medium, "").replace(glass, "");
    assert_ne!(ordered, REFS);
    let late = ordered.replace("</scene>", &format!("{medium}{glass}</scene>"));
    let b = xml("forward.xml", &late, &[]).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(b.media().len(), 1, "a medium referenced three times is one medium");
    assert_eq!(b.camera_medium(), Some(0));
    assert!(b.surfaces().iter().all(|f| f.exterior == Some(0) && f.interior.is_none()));
    // The same image, on a small film under a point light (a glass bsdf defined last is still glass).
    let small = |s: &str| {
        let film = r#"<film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="18"/></film>"#;
        s.replace(
            "</scene>",
            r#"<emitter type="point"><point name="position" x="1" y="2" z="3"/></emitter></scene>"#,
        )
        .replace(
            r#"<float name="fov" value="40"/>"#,
            &format!(r#"<float name="fov" value="40"/>{film}"#),
        )
    };
    assert_ne!(small(REFS), REFS);
    let (a, b) = (
        xml("in-order.xml", &small(REFS), &[]).unwrap(),
        xml("forward.xml", &small(&late), &[]).unwrap(),
    );
    let sum = |s: &Scene| image(s, 1).iter().map(|p| p[0] + p[1] + p[2]).sum::<f32>();
    assert!(sum(&a) > 0.0);
    assert_eq!(image(&a, 1), image(&b, 1));
    let diffuse = small(&late).replace(glass, r#"<bsdf type="diffuse" id="glass"/>"#);
    assert_ne!(sum(&a), sum(&xml("diffuse.xml", &diffuse, &[]).unwrap()));

    // A bsdf that holds itself through a later reference.
    let cycle = late.replace(glass, r#"<bsdf type="twosided" id="glass"><ref id="glass"/></bsdf>"#);
    let err = xml("cycle.xml", &cycle, &[]).expect_err("a cycle").to_string();
    assert!(err.contains("cycle.xml:") && err.contains("refers to itself"), "{err}");
    let unknown = late.replace("<ref id=\"haze\"/>", "<ref id=\"fog\"/>");
    let err = xml("unknown.xml", &unknown, &[]).expect_err("no such id").to_string();
    assert!(err.contains("unknown.xml:") && err.contains("id=\"fog\""), "{err}");
    // Each texture of a long chain names the next, defined after it.
    let chain: String = (0..200)
        .map(|i| {
            format!(
                r#"<texture type="checkerboard" id="t{i}"><ref name="color0" id="t{}"/></texture>"#,
                i + 1
            )
        })
        .collect();
    let deep = late.replace("</scene>", &format!("{chain}</scene>"));
    let err = xml("deep.xml", &deep, &[]).expect_err("too deep").to_string();
    assert!(err.contains("deep.xml:") && err.contains("nested more than"), "{err}");
    // Nesting within each object, each as deep as the reader allows, times a chain of
    // references: the whole depth is bounded too.
    let nested: String = (0..64)
        .map(|k| {
            let open = r#"<texture type="checkerboard" name="color0">"#.repeat(62);
            let close = "</texture>".repeat(62);
            format!(
                r#"<texture type="checkerboard" id="n{k}">{open}<ref name="color0" id="n{}"/>{close}</texture>"#,
                k + 1
            )
        })
        .collect();
    let deep = late.replace("</scene>", &format!("{nested}</scene>"));
    let err = xml("nested.xml", &deep, &[]).expect_err("too deep").to_string();
    assert!(err.contains("nested.xml:") && err.contains("through <ref>"), "{err}");
}

#[test]
fn defaults_overrides_and_refs() {
    let s = xml("refs.xml", REFS, &[]).unwrap();
    assert_eq!(s.media().len(), 1, "a medium referenced three times is one medium");
    assert_eq!(s.camera_medium(), Some(0));
    assert!(s.surfaces().iter().all(|f| f.exterior == Some(0) && f.interior.is_none()));
    assert_eq!(s.settings().max_depth, Some(8));
    assert_eq!(s.camera().resolution(), [768, 576], "Mitsuba's default film");
    assert_eq!(s.settings().spp, 4, "Mitsuba's default sampler");
    assert!((s.bounds().min.x + 0.5).abs() < 1e-6);
    let sigma = s.media()[0].majorant().to_array();
    assert!((sigma[0] - 0.4).abs() < 1e-6 && (sigma[2] - 0.6).abs() < 1e-6, "{sigma:?}");
    // -D overrides a default; an undeclared key is allowed, as in Mitsuba.
    let s = xml("refs.xml", REFS, &[("r", "2"), ("unused", "1")]).unwrap();
    assert!((s.bounds().min.x + 2.0).abs() < 1e-6);
    // -D may also define what no <default> declares.
    let text = REFS.replace("<default name=\"r\" value=\"0.5\"/>", "");
    assert!(xml("refs.xml", &text, &[("r", "1")]).is_ok());
    // Mitsuba's differentiable volumetric path tracer renders the image volpath renders.
    let prb = REFS.replace("type=\"volpathmis\"", "type=\"prbvolpath\"");
    assert_ne!(prb, REFS);
    assert_eq!(xml("prb.xml", &prb, &[]).unwrap().settings().max_depth, Some(8));
}

#[test]
fn includes_and_cyclic_includes() {
    let dir = temp_dir().join("include");
    std::fs::create_dir_all(dir.join("parts")).unwrap();
    let camera =
        r#"<scene><sensor type="perspective"><float name="fov" value="30"/></sensor></scene>"#;
    std::fs::write(dir.join("parts/camera.xml"), camera).unwrap();
    // A file name in an included file: relative to it, or else to the scene file (Mitsuba).
    std::fs::write(dir.join("near.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(dir.join("parts/far.obj"), "v 0 0 0\nv 2 0 0\nv 0 2 0\nf 1 2 3\n").unwrap();
    let shapes = r#"<scene version="3.0.0">
        <shape type="obj"><string name="filename" value="near.obj"/></shape>
        <shape type="obj"><string name="filename" value="far.obj"/></shape>
    </scene>"#;
    std::fs::write(dir.join("parts/shapes.xml"), shapes).unwrap();
    let main = "<scene version=\"3.0.0\">\n  <include filename=\"parts/camera.xml\"/>\n  \
                <include filename=\"parts/shapes.xml\"/>\n</scene>\n";
    std::fs::write(dir.join("main.xml"), main).unwrap();
    let s = zerovar::scene::load(&dir.join("main.xml"), &[]).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.shapes().len(), 2);
    assert_eq!(s.bounds().max.x, 2.0);

    let a = "<scene version=\"3.0.0\">\n  <include filename=\"b.xml\"/>\n</scene>\n";
    let b = "<scene version=\"3.0.0\">\n\n  <include filename=\"a.xml\"/>\n</scene>\n";
    std::fs::write(dir.join("a.xml"), a).unwrap();
    std::fs::write(dir.join("b.xml"), b).unwrap();
    let e = zerovar::scene::load(&dir.join("a.xml"), &[]).unwrap_err().to_string();
    assert!(e.contains("b.xml:3:3: cyclic include"), "{e}");
    assert!(e.contains("remove one of these includes"), "{e}");
}

/// The smallest valid Mitsuba scene, edited into bad ones here and in `lab/tests/cli.rs`.
const GOOD: &str = include_str!("data/minimal.xml");

/// Each edit of `GOOD` fails at `place` (`file:line:column`) with a message holding `needles`.
#[test]
fn bad_input_names_the_place_and_the_fix() {
    assert!(xml("good.xml", GOOD, &[]).is_ok());
    let radius = "<float name=\"radius\" value=\"1\"/>";
    let cases: &[(&str, &str, &str, &str, &[&str])] = &[
        ("tag", radius, "<sphere/>", "tag.xml:6:9", &["unknown element <sphere>", "shape"]),
        (
            "plugin",
            "type=\"sphere\"",
            "type=\"teapot\"",
            "plugin.xml:5:5",
            &[
                "unknown shape `teapot`",
                "sphere, cube, rectangle, disk, cylinder, obj, ply or serialized",
            ],
        ),
        (
            "cylinder-axis",
            "\"sphere\">\n        <float name=\"radius\" value=\"1\"/>",
            "\"cylinder\">\n        <point name=\"p0\" value=\"0, 1, 0\"/><point name=\"p1\" value=\"0, 1, 0\"/>",
            "cylinder-axis.xml:5",
            &["(cylinder)", "must be apart: they give the tube's axis"],
        ),
        (
            "cylinder-shear",
            "\"sphere\">\n        <float name=\"radius\" value=\"1\"/>",
            "\"cylinder\">\n        <transform name=\"to_world\"><scale x=\"2\"/></transform>",
            "cylinder-shear.xml:5",
            &["(cylinder)", "no shear, no mirroring: use an obj mesh"],
        ),
        (
            "type",
            radius,
            "<rgb name=\"radius\" value=\"1, 2, 3\"/>",
            "type.xml:6:9",
            &["<shape type=\"sphere\">", "`radius` must be a <float>, not <rgb>"],
        ),
        (
            "property",
            radius,
            "<float name=\"radus\" value=\"1\"/>",
            "property.xml:6:9",
            &["no property `radus`", "it takes center, radius"],
        ),
        (
            "missing",
            "\"sphere\">\n        <float name=\"radius\" value=\"1\"/>",
            "\"obj\">\n        <string name=\"filename\" value=\"nowhere.obj\"/>",
            "missing.xml:6:9",
            &["`filename`", "nowhere.obj not found"],
        ),
        (
            "malformed",
            "</shape>",
            "</shap>",
            "malformed.xml:7:5",
            &["malformed XML: expected 'shape' tag, not 'shap'"],
        ),
        ("number", "value=\"40\"", "value=\"forty\"", "number.xml:3:9", &["must be a number"]),
        (
            "default",
            "value=\"40\"",
            "value=\"$fov\"",
            "default.xml:3:9",
            &["`$fov`", "<default name=\"fov\""],
        ),
        (
            "ref",
            radius,
            "<ref id=\"glass\"/>",
            "ref.xml:6:9",
            &["<ref id=\"glass\"> names no object; define an object with id=\"glass\""],
        ),
        (
            "blend",
            radius,
            "<bsdf type=\"blendbsdf\"/>",
            "blend.xml:6:9",
            &["unsupported bsdf `blendbsdf`", "roughconductor"],
        ),
        (
            "thin",
            radius,
            "<bsdf type=\"thindielectric\"><string name=\"int_ior\" value=\"bk8\"/></bsdf>",
            "thin.xml:6:37",
            &["int_ior \"bk8\" is not one of Mitsuba's named materials", "give the index"],
        ),
        (
            "order",
            radius,
            "<bsdf type=\"diffuse\"><spectrum name=\"reflectance\" value=\"500:0.5, 400:0.2\"/></bsdf>",
            "order.xml:6:30",
            &["increasing order of wavelength; 400 nm follows 500 nm"],
        ),
        (
            "pair",
            radius,
            "<bsdf type=\"diffuse\"><spectrum name=\"reflectance\" value=\"500:0.5\"/></bsdf>",
            "pair.xml:6:30",
            &["at least two wavelength:value pairs"],
        ),
        (
            "nm",
            radius,
            "<bsdf type=\"diffuse\"><spectrum name=\"reflectance\" value=\"400:0.1, 500:\"/></bsdf>",
            "nm.xml:6:30",
            &["pairs of numbers (nm), not `500:`"],
        ),
        (
            "include",
            "<shape type=\"sphere\">",
            "<include filename=\"nothere.xml\"/><shape type=\"sphere\">",
            "include.xml:5:5",
            &["<include filename=\"nothere.xml\">: cannot read", "nothere.xml"],
        ),
        (
            "serialized",
            "type=\"sphere\"",
            "type=\"serialized\"",
            "serialized.xml:5:5",
            &["give the mesh as <string name=\"filename\""],
        ),
        ("ply", "type=\"sphere\"", "type=\"ply\"", "ply.xml:5:5", &["give the mesh as <string"]),
        (
            "pathint",
            radius,
            "<bsdf type=\"null\"/>",
            "pathint.xml:1:1",
            &["`path` integrator", "volpath"],
        ),
        (
            "depth",
            "<shape type=\"sphere\">",
            "<integrator type=\"path\"><integer name=\"max_depth\" value=\"-2\"/></integrator>\n<shape type=\"sphere\">",
            "depth.xml:5:5",
            &["<integrator type=\"path\">: max_depth -2 must be -1 (unlimited) or a depth >= 0"],
        ),
        (
            "version",
            "version=\"3.0.0\"",
            "version=\"0.6.0\"",
            "version.xml:1:1",
            &["version 2.x or 3.x"],
        ),
        (
            "area",
            "<shape type=\"sphere\">",
            "<emitter type=\"area\"/><shape type=\"sphere\">",
            "area.xml:5:5",
            &["inside the <shape>"],
        ),
        (
            "width",
            "<float name=\"fov\" value=\"40\"/>",
            "<float name=\"fov\" value=\"40\"/><film type=\"hdrfilm\"><integer name=\"width\" value=\"4294967312\"/></film>",
            "width.xml:3:39",
            &["width 4294967312 must be between 1 and 32768 pixels"],
        ),
        (
            "lanczos",
            "<float name=\"fov\" value=\"40\"/>",
            "<float name=\"fov\" value=\"40\"/><film type=\"hdrfilm\"><rfilter type=\"lanczos\"><integer name=\"lobes\" value=\"0\"/></rfilter></film>",
            "lanczos.xml:3:60",
            &["<rfilter type=\"lanczos\">", "lanczos lobes 0: give 1 to 8"],
        ),
        (
            "sinc",
            "<float name=\"fov\" value=\"40\"/>",
            "<float name=\"fov\" value=\"40\"/><film type=\"hdrfilm\"><rfilter type=\"sinc\"/></film>",
            "sinc.xml:3:60",
            &["the `sinc` pixel filter is not supported", "mitchell, catmullrom or lanczos"],
        ),
        (
            "wide-box",
            "<float name=\"fov\" value=\"40\"/>",
            "<float name=\"fov\" value=\"40\"/><film type=\"hdrfilm\"><rfilter type=\"box\"><float name=\"radius\" value=\"1\"/></rfilter></film>",
            "wide-box.xml:3:60",
            &["a box filter of radius 1", "use a tent or gaussian filter"],
        ),
        (
            "stddev",
            "<float name=\"fov\" value=\"40\"/>",
            "<float name=\"fov\" value=\"40\"/><film type=\"hdrfilm\"><rfilter type=\"gaussian\"><float name=\"stddev\" value=\"-0.5\"/></rfilter></film>",
            "stddev.xml:3:60",
            &["<rfilter type=\"gaussian\">", "stddev -0.5 must be a positive number of pixels"],
        ),
    ];
    let sky = "<emitter type=\"constant\"/>";
    let e = xml("sky.xml", &GOOD.replace("</scene>", &format!("{sky}\n{sky}\n</scene>")), &[]);
    let e = e.unwrap_err().to_string();
    assert!(e.contains("sky.xml:9:1: <emitter type=\"constant\">: a second environment"), "{e}");
    for (name, from, to, place, needles) in cases {
        assert!(GOOD.contains(from), "{name}");
        let file = format!("{name}.xml");
        let e = xml(&file, &GOOD.replacen(from, to, 1), &[]).unwrap_err().to_string();
        let place = temp_dir().join(place);
        assert!(e.starts_with(&format!("{}:", place.display())), "{name}: {e}");
        for n in *needles {
            assert!(e.contains(n), "{name}: `{n}` missing from: {e}");
        }
    }
}

#[test]
fn volumes_and_meshes_match_the_toml_format() {
    write("tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let mut albedo = Vec::new();
    zerovar::media::VolGrid::new([2, 1, 1], 1, vec![0.5, 0.9])
        .expect("a valid grid")
        .write(&mut albedo)
        .unwrap();
    write("albedo.vol", albedo);
    let box_ = r#"<transform name="to_world"><translate value="-0.5, -0.5, -0.5"/><scale value="2"/></transform>"#;
    let text = with_camera(
        r#"<lookat origin="0, 1, 5" target="0, 0, 0" up="0, 1, 0"/>"#,
        &format!(
            r#"<medium type="heterogeneous" id="m">
                <volume type="constvolume" name="sigma_t"><rgb name="value" value="2, 3, 4"/>{box_}</volume>
                <volume type="gridvolume" name="albedo"><string name="filename" value="albedo.vol"/>{box_}</volume>
                <float name="scale" value="0.5"/>
                <phase type="hg"/>
            </medium>
            <shape type="cube"><bsdf type="null"/><ref name="interior" id="m"/></shape>
            <shape type="obj">
                <string name="filename" value="tri.obj"/>
                <transform name="to_world"><translate y="-2"/></transform>
            </shape>
            <emitter type="constant"/>"#
        ),
    );
    let toml = r#"
[camera]
origin = [0, 1, 5]
target = [0, 0, 0]
fov = 50
fov_axis = "y"
resolution = [30, 40]
near_clip = 0.01
far_clip = 1e4

[media.m]
type = "grid"
density = 1
sigma_t = [2, 3, 4]
albedo = "albedo.vol"
scale = 0.5
phase = { type = "hg", g = 0.8 }
transform = [{ translate = [-0.5, -0.5, -0.5] }, { scale = 2 }]

[[shapes]]
type = "cube"
bsdf = { type = "null" }
interior = "m"

[[shapes]]
type = "obj"
filename = "tri.obj"
transform = [{ translate = [0, -2, 0] }]

[[lights]]
type = "constant"
radiance = 1
"#;
    let a = crate::common::scene(toml);
    let b = xml("volumes.xml", &text, &[]).unwrap_or_else(|e| panic!("{e}"));
    assert!(image(&a, 2) == image(&b, 2), "volumes: XML and TOML images differ");

    // An albedo grid in another box than the extinction's is an error.
    let other = text.replacen("<scale value=\"2\"/>", "<scale value=\"3\"/>", 1);
    let e = xml("volumes.xml", &other, &[]).unwrap_err().to_string();
    assert!(e.contains("the albedo grid must fill the same box as sigma_t"), "{e}");
}

#[test]
fn mitsuba_syntax_details() {
    let dir = temp_dir().join("syntax");
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::write(dir.join("meshes/m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(dir.join("null.xml"), r#"<scene version="3.0.0"><bsdf type="null"/></scene>"#)
        .unwrap();
    // `$ab` takes the longest name it goes on with; one value stands for x, y and z; a lookat
    // without up picks Mitsuba's perpendicular; a 3x3 matrix is the linear part; <path> adds a
    // directory; an include may sit inside an object.
    let text = r#"<scene version="3.0.0">
        <default name="a" value="0.25"/>
        <default name="ab" value="0.5"/>
        <path value="meshes"/>
        <integrator type="volpath"/>
        <sensor type="perspective">
            <float name="fov" value="30"/>
            <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0"/></transform>
        </sensor>
        <shape type="sphere">
            <point name="center" value="$a"/>
            <float name="radius" value="$ab"/>
            <include filename="null.xml"/>
        </shape>
        <shape type="obj">
            <string name="filename" value="m.obj"/>
            <transform name="to_world">
                <matrix value="0 -1 0  1 0 0  0 0 1"/>
                <translate value="0, 0, -3"/>
            </transform>
        </shape>
    </scene>"#;
    let path = dir.join("syntax.xml");
    std::fs::write(&path, text).unwrap();
    let s = zerovar::scene::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
    assert!(matches!(s.surfaces()[0].bsdf, zerovar::bsdf::Bsdf::Null));
    let b = s.bounds();
    // The sphere spans [-0.25, 0.75] on every axis, the rotated triangle x in [-1, 0].
    assert!((b.min - Vec3A::new(-1.0, -0.25, -3.0)).abs().max_element() < 1e-6, "{b:?}");
    assert!((b.max - Vec3A::new(0.75, 1.0, 0.75)).abs().max_element() < 1e-6, "{b:?}");
    let t = crate::common::scene(
        "[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nup = [1, 0, 0]\nfov = 30\n\
         resolution = [768, 576]\n",
    );
    for film in [Vec2::new(0.0, 0.0), Vec2::new(700.0, 100.0)] {
        let (a, b) = (t.camera().ray(film), s.camera().ray(film));
        assert!((a.direction - b.direction).abs().max_element() < 1e-6);
    }
}

#[test]
fn hostile_nesting_includes_and_repeats_are_errors_not_crashes() {
    // Deep nesting would overflow the reader's stack; it stops at 64 levels.
    let depth = 100_000;
    let deep = format!(
        "<scene version=\"3.0.0\">\n{}{}</scene>\n",
        "<bsdf type=\"twosided\">".repeat(depth),
        "</bsdf>".repeat(depth)
    );
    let e = xml("deep.xml", &deep, &[]).unwrap_err().to_string();
    assert!(e.contains("nested more than 64 deep"), "{e}");

    // A file including another twice, which includes the next twice, and so on: 2^20 reads
    // without a limit on includes.
    let dir = temp_dir().join("bomb");
    std::fs::create_dir_all(&dir).unwrap();
    for level in 0..20 {
        let next = format!("<include filename=\"l{}.xml\"/>\n", level + 1);
        let text = format!("<scene version=\"3.0.0\">\n{next}{next}</scene>\n");
        std::fs::write(dir.join(format!("l{level}.xml")), text).unwrap();
    }
    std::fs::write(dir.join("l20.xml"), "<scene version=\"3.0.0\">\n</scene>\n").unwrap();
    let e = zerovar::scene::load(&dir.join("l0.xml"), &[]).unwrap_err().to_string();
    assert!(e.contains("more than 1024 <include> elements"), "{e}");

    // A default given twice (an included preamble repeating the scene's) takes its first
    // value, as Mitsuba 3.9 does (checked with its Python loader); -D still overrides it.
    let twice = "<scene version=\"3.0.0\">\n  <default name=\"spp\" value=\"4\"/>\n  \
                 <default name=\"spp\" value=\"8\"/>\n  <sensor type=\"perspective\">\n    \
                 <float name=\"fov\" value=\"40\"/>\n    <sampler type=\"independent\">\
                 <integer name=\"sample_count\" value=\"$spp\"/></sampler>\n  </sensor>\n</scene>\n";
    assert_eq!(xml("twice.xml", twice, &[]).unwrap().settings().spp, 4);
    assert_eq!(xml("twice.xml", twice, &[("spp", "16")]).unwrap().settings().spp, 16);
}

/// As in Mitsuba, an emitting shape without a `<bsdf>` reflects nothing (a black diffuse
/// BSDF) while any other shape gets the diffuse 0.5 default; an explicit BSDF on an emitter is
/// kept. Found by the Mitsuba comparison (tests/mitsuba.rs, scene e), where light reflected off
/// the area light's own surface made zerovar 0.5% brighter.
#[test]
fn emitting_shape_without_bsdf_is_black_as_in_mitsuba() {
    use zerovar::bsdf::{Bsdf, Texture};
    use zerovar::math::Spectrum;
    let body = r#"
        <shape type="rectangle"><emitter type="area"/></shape>
        <shape type="rectangle"/>
        <shape type="disk">
            <bsdf type="diffuse"><rgb name="reflectance" value="0.3"/></bsdf>
            <emitter type="area"/>
        </shape>"#;
    let lookat = r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#;
    let s = xml("emitter-bsdf.xml", &with_camera(lookat, body), &[]).unwrap();
    let diffuse = |r: f32| Bsdf::Diffuse {
        reflectance: Texture::Constant(Spectrum::splat(r)),
        two_sided: false,
    };
    assert!(s.surfaces()[0].bsdf == diffuse(0.0), "{:?}", s.surfaces()[0].bsdf);
    assert!(s.surfaces()[1].bsdf == diffuse(0.5), "{:?}", s.surfaces()[1].bsdf);
    assert!(s.surfaces()[2].bsdf == diffuse(0.3), "{:?}", s.surfaces()[2].bsdf);
}

#[test]
fn ply_meshes_render_as_their_obj_twins_and_bad_ones_say_where() {
    // One quad (fan-triangulated) with vertex normals, as OBJ, ASCII PLY and big-endian PLY.
    write(
        "quad.obj",
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0.5\nv -1 1 0\nvn 0 0 1\nvn 0 0.3 1\nvn 0 0 1\nvn 0.2 0 1\n\
         f 1//1 2//2 3//3 4//4\n",
    );
    let ascii = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
        property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
        element face 1\nproperty list uchar int vertex_indices\nend_header\n\
        -1 -1 0 0 0 1\n1 -1 0 0 0.3 1\n1 1 0.5 0 0 1\n-1 1 0 0.2 0 1\n4 0 1 2 3\n";
    write("quad.ply", ascii);
    let mut big = b"ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty double x\n\
        property double y\nproperty double z\nproperty double nx\nproperty double ny\n\
        property double nz\nelement face 1\nproperty list uint short vertex_index\nend_header\n"
        .to_vec();
    for line in ascii.lines().skip(12).take(4) {
        for v in line.split(' ') {
            big.extend(v.parse::<f64>().unwrap().to_be_bytes());
        }
    }
    big.extend(4u32.to_be_bytes());
    for i in 0..4i16 {
        big.extend(i.to_be_bytes());
    }
    write("quad-be.ply", &big);
    let scene = |kind: &str, file: &str, extra: &str| {
        with_camera(
            r#"<lookat origin="0.5, 1, 4" target="0, 0, 0" up="0, 1, 0"/>"#,
            &format!(
                r#"<shape type="{kind}">
                    <string name="filename" value="{file}"/>{extra}
                    <transform name="to_world"><rotate x="1" angle="-20"/></transform>
                </shape>
                <emitter type="directional"><vector name="direction" value="0.3, -0.4, -1"/></emitter>
                <emitter type="constant"><float name="radiance" value="0.2"/></emitter>"#
            ),
        )
    };
    let obj = xml("quad-obj.xml", &scene("obj", "quad.obj", ""), &[]).unwrap();
    let reference = image(&obj, 3);
    assert!(reference.iter().any(|p| p[0] > 0.0));
    for file in ["quad.ply", "quad-be.ply"] {
        let ply =
            xml("quad-ply.xml", &scene("ply", file, ""), &[]).unwrap_or_else(|e| panic!("{e}"));
        assert!(image(&ply, 3) == reference, "{file}: the PLY quad renders unlike the OBJ one");
    }
    // face_normals drops the vertex normals in both formats alike.
    let flat = r#"<boolean name="face_normals" value="true"/>"#;
    let a = xml("quad-obj-flat.xml", &scene("obj", "quad.obj", flat), &[]).unwrap();
    let b = xml("quad-ply-flat.xml", &scene("ply", "quad.ply", flat), &[]).unwrap();
    let flat_image = image(&a, 3);
    assert!(image(&b, 3) == flat_image && flat_image != reference);

    // The TOML format takes `type = "ply"` as it takes "obj".
    let toml = |kind: &str, file: &str| {
        format!(
            "[camera]\norigin = [0.5, 1, 4]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [12, 9]\n\
             [[shapes]]\ntype = \"{kind}\"\nfilename = \"{}\"\n\
             [[lights]]\ntype = \"constant\"\nradiance = 1\n",
            temp_dir().join(file).display()
        )
    };
    let a = crate::common::scene(&toml("obj", "quad.obj"));
    let b = crate::common::scene(&toml("ply", "quad-be.ply"));
    assert!(image(&a, 4) == image(&b, 4), "TOML: the PLY quad renders unlike the OBJ one");

    // A broken file is an error naming the file and the place in it.
    write("bad.ply", ascii.replace("4 0 1 2 3", "4 0 1 2 9"));
    let e = xml("bad-ply.xml", &scene("ply", "bad.ply", ""), &[]).unwrap_err().to_string();
    assert!(e.contains("bad.ply: PLY data at line 17: face 0 refers to vertex 9"), "{e}");
    write("short.ply", &big[..big.len() - 5]);
    let e = xml("short-ply.xml", &scene("ply", "short.ply", ""), &[]).unwrap_err().to_string();
    assert!(e.contains("short.ply: PLY data at byte") && e.contains("truncated"), "{e}");
}

#[test]
fn rotation_about_a_non_unit_axis_is_mitsubas_matrix() {
    // Mitsuba 3.9.1 does not normalise a <rotate> axis: this cube's bounding box there is
    // [-0.0526547, -0.152655, -0.979783] to [2.05265, 1.95265, 1.37978] (with the axis
    // normalised it would be about 0.6 * 1.6 across, not 2.1).
    let text = with_camera(
        r#"<lookat origin="0, 1, 5" target="0, 0, 0" up="0, 1, 0"/>"#,
        r#"<shape type="cube">
            <transform name="to_world">
                <scale value="0.6"/>
                <rotate x="1" y="1" angle="35"/>
                <translate value="1, 0.9, 0.2"/>
            </transform>
        </shape>"#,
    );
    let b = xml("rotate-axis.xml", &text, &[]).unwrap_or_else(|e| panic!("{e}")).bounds();
    let (min, max) = (
        Vec3A::new(-0.052_654_7, -0.152_655, -0.979_783),
        Vec3A::new(2.052_65, 1.952_65, 1.379_78),
    );
    assert!(
        (b.min - min).abs().max_element() < 1e-5 && (b.max - max).abs().max_element() < 1e-5,
        "{b:?}"
    );
}

/// Mitsuba's depth counting at its ends: `max_depth` 0 renders black, 1 shows only what the
/// camera sees emit (the area light), 2 adds its direct light on the walls.
#[test]
fn max_depth_zero_is_black_and_one_is_emitters_only() {
    let text = std::fs::read_to_string(repo("tests/data/mitsuba/k-fog-room-walls.xml")).unwrap();
    let mean = |depth: u32| {
        let t = text.replace(
            "<integer name=\"max_depth\" value=\"8\"/>",
            &format!("<integer name=\"max_depth\" value=\"{depth}\"/>"),
        );
        assert_ne!(t, text);
        let s = xml(&format!("depth{depth}.xml"), &t, &[]).unwrap();
        let img = image(&s, 3);
        (
            img.iter().map(|p| p[0]).sum::<f32>() / img.len() as f32,
            img.iter().filter(|p| p[0] > 0.0).count(),
        )
    };
    let (zero, one, two) = (mean(0), mean(1), mean(2));
    assert_eq!(zero, (0.0, 0), "max_depth 0 must render black");
    // The light's own radiance in the pixels that see it, nothing elsewhere.
    assert!(one.0 > 0.0 && one.1 < 20, "max_depth 1: {one:?}");
    assert!(two.0 > one.0 && two.1 > 300, "max_depth 2: {two:?}");
}

/// `hide_emitters` removes exactly what the camera sees of emitters before any scattering
/// event: through fog and null crossings, the hidden image plus the emitters-only image
/// (`max_depth` 1, the same random numbers) is the visible one; against a sky, the pixels that
/// see only the sky are black and those that see only the sphere are unchanged.
#[test]
fn hide_emitters_hides_what_the_camera_sees_directly_and_nothing_else() {
    let text = std::fs::read_to_string(repo("tests/data/mitsuba/k-fog-room-walls.xml")).unwrap();
    let render_with = |name: &str, edits: &[(&str, &str)]| {
        let mut t = text.clone();
        for (from, to) in edits {
            assert!(t.contains(from), "{from}");
            t = t.replace(from, to);
        }
        image(&xml(name, &t, &[]).unwrap(), 3)
    };
    let depth = "<integer name=\"max_depth\" value=\"8\"/>";
    let hide =
        "<integer name=\"max_depth\" value=\"8\"/><boolean name=\"hide_emitters\" value=\"true\"/>";
    let visible = render_with("shown.xml", &[]);
    let hidden = render_with("hidden.xml", &[(depth, hide)]);
    let direct = render_with("direct.xml", &[(depth, "<integer name=\"max_depth\" value=\"1\"/>")]);
    let mut seen = 0;
    for ((v, h), d) in visible.iter().zip(&hidden).zip(&direct) {
        seen += usize::from(d[0] > 0.0);
        for c in 0..3 {
            let sum = h[c] + d[c];
            assert!(
                (v[c] - sum).abs() <= 1e-5 * v[c].max(1.0),
                "visible {v:?}, hidden {h:?} + direct {d:?}"
            );
        }
    }
    assert!(seen > 0, "the camera must see the light in some pixels");

    let body = r#"
        <shape type="sphere"><float name="radius" value="1"/></shape>
        <emitter type="constant"><rgb name="radiance" value="0.8"/></emitter>"#;
    let lookat = r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#;
    let sky = with_camera(lookat, body);
    let shown = image(&xml("sky-shown.xml", &sky, &[]).unwrap(), 5);
    let hidden_sky = sky.replace(
        "<integrator type=\"volpath\"/>",
        "<integrator type=\"volpath\"><boolean name=\"hide_emitters\" value=\"true\"/></integrator>",
    );
    let hidden = image(&xml("sky-hidden.xml", &hidden_sky, &[]).unwrap(), 5);
    let [w, h] = xml("sky-shown.xml", &sky, &[]).unwrap().camera().resolution();
    let (corner, centre) = (0, (h / 2 * w + w / 2) as usize);
    assert!(
        shown[corner][0] > 0.5 && hidden[corner] == [0.0; 3],
        "{:?} {:?}",
        shown[corner],
        hidden[corner]
    );
    assert!(
        shown[centre][0] > 0.0 && hidden[centre] == shown[centre],
        "{:?} {:?}",
        shown[centre],
        hidden[centre]
    );
}

/// A sensor without `fov` takes Mitsuba's 50 mm lens on 36 x 24 mm film (or `focal_length`),
/// its field of view along the image's diagonal: the horizontal angles are Mitsuba 3.9's own
/// `x_fov` for these films.
#[test]
fn focal_lengths_give_mitsubas_fields_of_view() {
    for (w, h, focal, x_fov) in [
        (48, 48, "", 34.022_057),
        (48, 48, "35mm", 47.216_316),
        (64, 32, "", 42.311_714),
        (30, 60, "35mm", 30.903_755),
    ] {
        let lens = if focal.is_empty() {
            String::new()
        } else {
            format!("<string name=\"focal_length\" value=\"{focal}\"/>")
        };
        let text = format!(
            "<scene version=\"3.0.0\"><sensor type=\"perspective\">{lens}<film type=\"hdrfilm\">\
             <integer name=\"width\" value=\"{w}\"/><integer name=\"height\" value=\"{h}\"/>\
             </film></sensor><shape type=\"sphere\"/></scene>"
        );
        let s = xml("lens.xml", &text, &[]).unwrap();
        let centre = s.camera().ray(Vec2::new(w as f32 / 2.0, h as f32 / 2.0)).direction;
        let edge = s.camera().ray(Vec2::new(0.0, h as f32 / 2.0)).direction;
        let half = centre.dot(edge).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(
            (2.0 * half - x_fov).abs() < 1e-3,
            "{w}x{h} {focal:?}: {} against {x_fov}",
            2.0 * half
        );
    }
    // `fov_axis` in any case, and across the diagonal: from the centre to a corner is half
    // the field of view.
    let axis = |axis: &str| {
        let text = format!(
            "<scene version=\"3.0.0\"><sensor type=\"perspective\"><float name=\"fov\" value=\"60\"/>\
             <string name=\"fov_axis\" value=\"{axis}\"/><film type=\"hdrfilm\">\
             <integer name=\"width\" value=\"64\"/><integer name=\"height\" value=\"32\"/>\
             </film></sensor><shape type=\"sphere\"/></scene>"
        );
        xml("axis.xml", &text, &[]).unwrap_or_else(|e| panic!("{axis}: {e}"))
    };
    let corner = Vec2::new(0.0, 0.0);
    assert_eq!(axis("Y").camera().ray(corner).direction, axis("y").camera().ray(corner).direction);
    let s = axis("diagonal");
    let centre = s.camera().ray(Vec2::new(32.0, 16.0)).direction;
    let half = centre.dot(s.camera().ray(corner).direction).clamp(-1.0, 1.0).acos().to_degrees();
    assert!((half - 30.0).abs() < 1e-3, "{half}");
    let both = "<scene version=\"3.0.0\"><sensor type=\"perspective\"><float name=\"fov\" value=\"40\"/>\
                <string name=\"focal_length\" value=\"35mm\"/></sensor></scene>";
    let e = xml("both.xml", both, &[]).unwrap_err().to_string();
    assert!(e.contains("either `fov` or `focal_length`"), "{e}");
    let bad = "<scene version=\"3.0.0\"><sensor type=\"perspective\">\
               <string name=\"focal_length\" value=\"long\"/></sensor></scene>";
    let e = xml("lens-bad.xml", bad, &[]).unwrap_err().to_string();
    assert!(e.contains("focal_length \"long\" is not a length in millimetres"), "{e}");
}

/// Mitsuba's named indices of refraction, in any case; an unknown name lists the known ones.
#[test]
fn named_indices_of_refraction() {
    use zerovar::bsdf::Bsdf;
    let glass = |int: &str, ext: &str| {
        format!(
            "<scene version=\"3.0.0\"><sensor type=\"perspective\"><float name=\"fov\" value=\"40\"/>\
             </sensor><shape type=\"sphere\"><bsdf type=\"dielectric\"><string name=\"int_ior\" \
             value=\"{int}\"/><string name=\"ext_ior\" value=\"{ext}\"/></bsdf></shape></scene>"
        )
    };
    let s = xml("water.xml", &glass("Water", "air"), &[]).unwrap();
    match s.surfaces()[0].bsdf {
        Bsdf::Dielectric { eta } => assert!((eta - 1.333 / 1.000_277).abs() < 1e-6, "{eta}"),
        ref b => panic!("{b:?}"),
    }
    let e = xml("unobtainium.xml", &glass("unobtainium", "air"), &[]).unwrap_err().to_string();
    assert!(
        e.contains("int_ior \"unobtainium\" is not one of Mitsuba's named") && e.contains("bk7"),
        "{e}"
    );
}

/// A scene of one sphere with `bsdf`.
fn sphere_with(bsdf: &str) -> String {
    format!(
        "<scene version=\"3.0.0\"><sensor type=\"perspective\"><float name=\"fov\" value=\"40\"/>\
         </sensor><shape type=\"sphere\">{bsdf}</shape></scene>"
    )
}

/// Mitsuba's `plastic` with its defaults (polypropylene in air, base 0.5, specular 1), its
/// parameters, and wrapped in `twosided`; `twosided` around a BSDF zerovar has no two-sided
/// form of is refused.
#[test]
fn plastic_defaults_parameters_and_two_sides() {
    use zerovar::bsdf::{Bsdf, Plastic, Texture};
    use zerovar::math::Spectrum;
    let s = xml("plastic.xml", &sphere_with("<bsdf type=\"plastic\"/>"), &[]).unwrap();
    let default = Plastic::new(
        Texture::Constant(Spectrum::splat(0.5)),
        Spectrum::ONE,
        1.49 / 1.000_277,
        false,
    );
    assert_eq!(s.surfaces()[0].bsdf, Bsdf::Plastic(default));
    let given = "<bsdf type=\"twosided\"><bsdf type=\"plastic\"><rgb name=\"diffuse_reflectance\" \
                 value=\"0.2, 0.4, 0.6\"/><float name=\"specular_reflectance\" value=\"0.5\"/>\
                 <string name=\"int_ior\" value=\"water\"/><boolean name=\"nonlinear\" value=\"true\"/>\
                 </bsdf></bsdf>";
    let s = xml("plastic-2.xml", &sphere_with(given), &[]).unwrap();
    let expected = Plastic::new(
        Texture::Constant(Spectrum::new(0.2, 0.4, 0.6)),
        Spectrum::splat(0.5),
        1.333 / 1.000_277,
        true,
    )
    .with_two_sided(true);
    assert_eq!(s.surfaces()[0].bsdf, Bsdf::Plastic(expected));
    let rough = "<bsdf type=\"twosided\"><bsdf type=\"dielectric\"/></bsdf>";
    let e = xml("plastic-3.xml", &sphere_with(rough), &[]).unwrap_err().to_string();
    assert!(
        e.contains(
            "surfaces are diffuse, plastic, conductor or their rough kinds, not `dielectric`"
        ),
        "{e}"
    );
}

/// `roughplastic` and `roughdielectric`: Mitsuba's defaults (Beckmann, alpha 0.1,
/// polypropylene and BK7 inside, air outside), given parameters, twosided rough plastic, and
/// clear errors for what zerovar lacks.
#[test]
fn rough_bsdfs_defaults_parameters_and_errors() {
    use zerovar::bsdf::{Bsdf, Microfacet, MicrofacetKind, RoughDielectric, RoughPlastic, Texture};
    use zerovar::math::Spectrum;
    let beckmann = Microfacet::isotropic(MicrofacetKind::Beckmann, 0.1);
    let s = xml("rough.xml", &sphere_with("<bsdf type=\"roughplastic\"/>"), &[]).unwrap();
    let grey = Texture::Constant(Spectrum::splat(0.5));
    let default = RoughPlastic::new(grey.clone(), Spectrum::ONE, 1.49 / 1.000_277, false, beckmann);
    assert_eq!(s.surfaces()[0].bsdf, Bsdf::RoughPlastic(default));
    let s = xml("rough-2.xml", &sphere_with("<bsdf type=\"roughdielectric\"/>"), &[]).unwrap();
    let glass = RoughDielectric { roughness: beckmann.into(), eta: 1.5046 / 1.000_277 };
    assert_eq!(s.surfaces()[0].bsdf, Bsdf::RoughDielectric(glass));
    let given = "<bsdf type=\"twosided\"><bsdf type=\"roughplastic\"><string name=\"distribution\" \
                 value=\"GGX\"/><float name=\"alpha\" value=\"0.3\"/><boolean name=\"sample_visible\" \
                 value=\"false\"/><float name=\"int_ior\" value=\"1.5\"/></bsdf></bsdf>";
    let s = xml("rough-3.xml", &sphere_with(given), &[]).unwrap();
    let ggx = Microfacet::isotropic(MicrofacetKind::Ggx, 0.3);
    let expected = RoughPlastic::new(grey, Spectrum::ONE, 1.5 / 1.000_277, false, ggx);
    assert_eq!(s.surfaces()[0].bsdf, Bsdf::RoughPlastic(expected.with_two_sided(true)));
    for (bsdf, needle) in [
        (
            "<bsdf type=\"roughdielectric\"><float name=\"alpha_u\" value=\"0.1\"/></bsdf>",
            "anisotropic roughness needs both `alpha_u` and `alpha_v`",
        ),
        (
            "<bsdf type=\"roughconductor\"><float name=\"alpha\" value=\"0.1\"/>\
             <float name=\"alpha_u\" value=\"0.1\"/><float name=\"alpha_v\" value=\"0.2\"/></bsdf>",
            "give either `alpha` or `alpha_u` and `alpha_v`, not both",
        ),
        (
            "<bsdf type=\"roughplastic\"><float name=\"alpha_u\" value=\"0.1\"/>\
             <float name=\"alpha_v\" value=\"0.2\"/></bsdf>",
            "a roughplastic takes one `alpha`, as in Mitsuba",
        ),
        (
            "<bsdf type=\"roughplastic\"><texture type=\"checkerboard\" name=\"alpha\"/></bsdf>",
            "a roughplastic's `alpha` is a number, as in Mitsuba",
        ),
        (
            "<bsdf type=\"roughconductor\"><texture type=\"checkerboard\" name=\"alpha\">\
             <float name=\"color0\" value=\"0\"/></texture></bsdf>",
            "alpha down to 0 is not a roughness zerovar renders",
        ),
        (
            "<bsdf type=\"roughplastic\"><string name=\"distribution\" value=\"phong\"/></bsdf>",
            "unknown microfacet distribution `phong`; use beckmann or ggx",
        ),
        (
            "<bsdf type=\"roughdielectric\"><float name=\"alpha\" value=\"0\"/></bsdf>",
            "alpha 0 is not a roughness zerovar renders: give at least 0.0001",
        ),
        (
            "<bsdf type=\"roughdielectric\"><float name=\"int_ior\" value=\"1.2\"/>\
             <float name=\"ext_ior\" value=\"1.2\"/></bsdf>",
            "a rough dielectric needs int_ior and ext_ior to differ",
        ),
        (
            "<bsdf type=\"roughconductor\"><string name=\"material\" value=\"unobtainium\"/></bsdf>",
            "material \"unobtainium\" is not one of Mitsuba's conductors (none, a-C, Ag",
        ),
        (
            "<bsdf type=\"conductor\"><string name=\"material\" value=\"Au\"/>\
             <float name=\"eta\" value=\"1\"/></bsdf>",
            "either `material` or `eta` and `k`, not both",
        ),
        ("<bsdf type=\"conductor\"><float name=\"alpha\" value=\"0.1\"/></bsdf>", "alpha"),
    ] {
        let e = xml("rough-bad.xml", &sphere_with(bsdf), &[]).unwrap_err().to_string();
        assert!(e.contains(needle), "{bsdf}: {e}");
        assert!(e.contains("rough-bad.xml:1:"), "names the file and line: {e}");
    }
}

/// `conductor` and `roughconductor`: Mitsuba's default (`none`, a perfect mirror; Beckmann,
/// alpha 0.1), a named material, given `eta` and `k` (the other defaulting), and twosided.
#[test]
fn conductors_defaults_materials_and_sides() {
    use zerovar::bsdf::{Bsdf, Conductor, Metal, Microfacet, MicrofacetKind, RoughConductor};
    use zerovar::math::Spectrum;
    let load = |name: &str, bsdf: &str| {
        xml(name, &sphere_with(bsdf), &[]).unwrap().surfaces()[0].bsdf.clone()
    };
    let mirror =
        Metal { eta: Spectrum::ZERO, k: Spectrum::ONE, specular: Spectrum::ONE, two_sided: false };
    let beckmann = Microfacet::isotropic(MicrofacetKind::Beckmann, 0.1);
    assert_eq!(load("metal.xml", "<bsdf type=\"conductor\"/>"), Bsdf::Conductor(Conductor(mirror)));
    assert_eq!(
        load("metal-2.xml", "<bsdf type=\"roughconductor\"/>"),
        Bsdf::RoughConductor(RoughConductor { metal: mirror, roughness: beckmann.into() })
    );
    let (eta, k) = Metal::named("Au").unwrap();
    let gold = "<bsdf type=\"twosided\"><bsdf type=\"roughconductor\"><string name=\"material\" \
                value=\"Au\"/><string name=\"distribution\" value=\"ggx\"/><float name=\"alpha\" \
                value=\"0.2\"/><rgb name=\"specular_reflectance\" value=\"0.5, 0.6, 0.7\"/></bsdf></bsdf>";
    let metal = Metal { eta, k, specular: Spectrum::new(0.5, 0.6, 0.7), two_sided: true };
    let roughness = Microfacet::isotropic(MicrofacetKind::Ggx, 0.2).into();
    assert_eq!(
        load("metal-3.xml", gold),
        Bsdf::RoughConductor(RoughConductor { metal, roughness })
    );
    let given = "<bsdf type=\"conductor\"><rgb name=\"eta\" value=\"0.2, 0.9, 1.1\"/></bsdf>";
    let metal = Metal { eta: Spectrum::new(0.2, 0.9, 1.1), ..mirror };
    assert_eq!(load("metal-4.xml", given), Bsdf::Conductor(Conductor(metal)));
}

/// `<spectrum type="d65">` reads as Mitsuba's RGB variants read it, white times its `scale`,
/// in emitters and reflectances alike; `blackbody`, which they refuse, and other types are
/// errors that say what to write instead.
#[test]
fn typed_spectra_as_mitsubas_rgb_variants() {
    let emitting = |radiance: &str| {
        format!(
            "<scene version=\"3.0.0\"><sensor type=\"perspective\"><float name=\"fov\" value=\"40\"/>\
             </sensor><shape type=\"sphere\"><emitter type=\"area\">{radiance}</emitter>\
             <bsdf type=\"diffuse\"><spectrum name=\"reflectance\" type=\"d65\"/></bsdf></shape></scene>"
        )
    };
    let d65 =
        "<spectrum name=\"radiance\" type=\"d65\"><float name=\"scale\" value=\"2\"/></spectrum>";
    let a = xml("d65.xml", &emitting(d65), &[]).unwrap();
    let b = xml("rgb.xml", &emitting("<rgb name=\"radiance\" value=\"2\"/>"), &[]).unwrap();
    assert_eq!(format!("{:?}", a.lights()), format!("{:?}", b.lights()));
    let white = zerovar::bsdf::Texture::Constant(zerovar::math::Spectrum::ONE);
    assert_eq!(
        a.surfaces()[0].bsdf,
        zerovar::bsdf::Bsdf::Diffuse { reflectance: white, two_sided: false }
    );
    for (radiance, needle) in [
        (
            "<spectrum name=\"radiance\" type=\"blackbody\"><float name=\"temperature\" value=\"5000\"/></spectrum>",
            "a blackbody spectrum exists only in Mitsuba's spectral variants",
        ),
        (
            "<spectrum name=\"radiance\" type=\"regular\"/>",
            "<spectrum type=\"regular\"> is not supported",
        ),
        (
            "<spectrum name=\"radiance\" type=\"d65\"><float name=\"gain\" value=\"2\"/></spectrum>",
            "takes only <float name=\"scale\">",
        ),
    ] {
        let e = xml("typed.xml", &emitting(radiance), &[]).unwrap_err().to_string();
        assert!(e.contains(needle) && e.contains("typed.xml:1:"), "{radiance}: {e}");
    }
}

/// Mitsuba's `bitmap` texture: a PNG read as sRGB, looked up with the image's top at v = 0
/// (its agreement with Mitsuba is tests/mitsuba.rs's `q-bitmap`); formats, filters, wrap modes
/// and values zerovar does not take are errors that say what to do.
#[test]
fn bitmap_textures_and_their_errors() {
    use zerovar::bsdf::{Bsdf, Texture};
    let png = std::fs::read(repo("tests/data/mitsuba/tex-5x3.png")).unwrap();
    write("tex.png", &png);
    write("tex.jpg", &png);
    write("tex.gif", &png);
    let bright = temp_dir().join("bright.exr");
    let meta =
        zerovar::output::ImageMetadata { spp: 1, seconds: 0.0, seed: 0, scene: String::new() };
    zerovar::output::write_exr(&bright, 1, 1, &[[1.5, 0.5, 0.5]], &meta).unwrap();
    let textured = |texture: &str| {
        sphere_with(&format!(
            "<bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">{texture}\
             </texture></bsdf>"
        ))
    };
    let s = xml("bitmap.xml", &textured("<string name=\"filename\" value=\"tex.png\"/>"), &[]);
    let s = s.unwrap();
    let Bsdf::Diffuse { reflectance: t @ Texture::Bitmap(_), .. } = &s.surfaces()[0].bsdf else {
        panic!("{:?}", s.surfaces()[0].bsdf)
    };
    // The top-left texel (pure red in the file) at its centre; bottom-right pure blue.
    assert_eq!(t.eval(Vec2::new(0.1, 1.0 / 6.0)).to_array(), [1.0, 0.0, 0.0]);
    assert_eq!(t.eval(Vec2::new(0.9, 5.0 / 6.0)).to_array(), [0.0, 0.0, 1.0]);
    for (texture, needle) in [
        ("<string name=\"filename\" value=\"tex.jpg\"/>", "tex.jpg: cannot read JPEG"),
        (
            "<string name=\"filename\" value=\"tex.gif\"/>",
            "reads OpenEXR, Radiance HDR (.hdr), PNG and JPEG",
        ),
        ("<string name=\"filename\" value=\"missing.png\"/>", "missing.png not found"),
        ("<string name=\"filename\" value=\"bright.exr\"/>", "texel values reach 1.5"),
        (
            "<string name=\"filename\" value=\"tex.png\"/><string name=\"filter_type\" value=\"cubic\"/>",
            "filter_type `cubic`: use bilinear or nearest",
        ),
        (
            "<string name=\"filename\" value=\"tex.png\"/><string name=\"wrap_mode\" value=\"zero\"/>",
            "wrap_mode `zero`: use repeat, mirror or clamp",
        ),
        ("<float name=\"gamma\" value=\"2\"/>", "give the image as <string name=\"filename\""),
    ] {
        let e = xml("bitmap-bad.xml", &textured(texture), &[]).unwrap_err().to_string();
        assert!(e.contains(needle), "{texture}: {e}");
    }
}

/// Mitsuba's `mask`: its default opacity, a nested BSDF (here two-sided), and errors for what
/// zerovar does not take: a mask without a BSDF, around one light passes itself, an
/// out-of-range opacity (constant or textured), and masks under Mitsuba's `path` integrator.
#[test]
fn masks_and_their_errors() {
    use zerovar::bsdf::{Bsdf, Texture};
    use zerovar::math::Spectrum;
    let volpath =
        |bsdf: &str| sphere_with(bsdf).replace("<sensor", "<integrator type=\"volpath\"/><sensor");
    let diffuse = "<bsdf type=\"twosided\"><bsdf type=\"diffuse\"/></bsdf>";
    let s = xml("mask.xml", &volpath(&format!("<bsdf type=\"mask\">{diffuse}</bsdf>")), &[]);
    let grey = Texture::Constant(Spectrum::splat(0.5));
    let nested = Box::new(Bsdf::Diffuse { reflectance: grey, two_sided: true });
    let half = Texture::Constant(Spectrum::splat(0.5));
    assert_eq!(s.unwrap().surfaces()[0].bsdf, Bsdf::Mask { opacity: half, nested });
    for (bsdf, needle) in [
        ("<bsdf type=\"mask\"/>", "mask wraps exactly one <bsdf>"),
        (
            "<bsdf type=\"mask\"><bsdf type=\"thindielectric\"/></bsdf>",
            "a mask around a `thindielectric` (which light passes itself) is not supported",
        ),
        (
            "<bsdf type=\"mask\"><float name=\"opacity\" value=\"1.5\"/><bsdf type=\"diffuse\"/></bsdf>",
            "opacity 1.5 exceeds 1: it is a share of light, in [0, 1]",
        ),
        (
            "<bsdf type=\"mask\"><texture type=\"checkerboard\" name=\"opacity\">\
             <float name=\"color1\" value=\"2\"/></texture><bsdf type=\"diffuse\"/></bsdf>",
            "color1 2 exceeds 1",
        ),
    ] {
        let e = xml("mask-bad.xml", &volpath(bsdf), &[]).unwrap_err().to_string();
        assert!(e.contains(needle) && e.contains("mask-bad.xml:1:"), "{bsdf}: {e}");
    }
    let path = sphere_with("<bsdf type=\"mask\"><bsdf type=\"diffuse\"/></bsdf>")
        .replace("<sensor", "<integrator type=\"path\"/><sensor");
    let e = xml("mask-path.xml", &path, &[]).unwrap_err().to_string();
    assert!(e.contains("a mask under Mitsuba's `path` integrator is not supported"), "{e}");
}

/// Mitsuba's sensor starts its rays on the near clipping plane (0.01 from the eye by default)
/// and sees nothing beyond the far one (1e4): a camera in a medium skips the medium before
/// the near plane, and surfaces outside the two planes are not seen.
#[test]
fn camera_rays_run_between_mitsubas_clipping_planes() {
    use zerovar::guided::NoCache;
    use zerovar::integrators::VolPath;
    use zerovar::integrators::walk::{PathStart, WalkContext, radiance};
    use zerovar::rng::Sampler;
    use zerovar::stats::Counters;
    use zerovar_testkit::MeanEstimate;

    // An absorbing medium around the camera, 5 units from a large emitting rectangle that
    // faces it: along the view axis the pixel sees exp(-sigma_t (5 - near)).
    let scene = |clip: &str| {
        let lookat = r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#;
        let camera = CAMERA
            .replace("TO_WORLD", lookat)
            .replace("<film", &format!("{clip}<ref id=\"dark\"/><film"));
        let text = format!(
            r#"<scene version="3.0.0">
            <medium type="homogeneous" id="dark">
                <float name="sigma_t" value="0.2"/>
                <float name="albedo" value="0"/>
            </medium>{camera}
            <integrator type="volpath"/>
            <shape type="rectangle">
                <transform name="to_world"><scale value="100"/></transform>
                <emitter type="area"><rgb name="radiance" value="1"/></emitter>
            </shape></scene>"#
        );
        xml("clip.xml", &text, &[]).unwrap_or_else(|e| panic!("{e}"))
    };
    let axis = Vec2::new(15.0, 20.0); // the film's centre: the view axis
    let seen = |s: &Scene| {
        let settings = VolPath::from_scene(s).settings();
        let mut counters = Counters::default();
        let est: MeanEstimate = (0..40_000)
            .map(|i| {
                let mut sampler = Sampler::new(9, 0, i);
                let mut cache = NoCache;
                let mut ctx = WalkContext::new(&mut cache);
                let start = PathStart::camera(s, axis, &mut sampler);
                f64::from(radiance(&settings, s, start, &mut ctx, &mut sampler, &mut counters).x)
            })
            .collect();
        est
    };
    let clip = |near: f32, far: f32| {
        format!(r#"<float name="near_clip" value="{near}"/><float name="far_clip" value="{far}"/>"#)
    };
    // Mitsuba's defaults, then a near plane 2 units out: transmittances 0.369 and 0.549, each
    // estimated to about 0.7%.
    for (s, near) in [(scene(""), 0.01f64), (scene(&clip(2.0, 1e4)), 2.0)] {
        let (ray, reach) = s.camera().ray_and_reach(axis, Vec2::splat(0.5));
        assert!((f64::from(ray.origin.z) - (5.0 - near)).abs() < 1e-5, "{}", ray.origin);
        let (est, expected) = (seen(&s), (-0.2 * (5.0 - near)).exp());
        // Closed-form tracking may weigh the flight by its transmittance exactly.
        if est.std_error() > 0.0 {
            est.assert_matches(expected, 4.5, &format!("near_clip {near}"));
        } else {
            assert!((est.mean / expected - 1.0).abs() < 1e-5, "near_clip {near}: {est:?}");
        }
        assert!(reach > 9000.0);
    }
    // The rectangle before the near plane or beyond the far one is not seen.
    for (near, far) in [(5.5, 1e4), (0.01, 4.0)] {
        let s = scene(&clip(near, far));
        let est = seen(&s);
        assert_eq!(est.mean, 0.0, "near {near}, far {far}: the rectangle was seen");
    }
    // Mitsuba's own rules for the two planes.
    for (near, far, what) in [
        (0.0, 1e4, "near_clip 0 must be greater than 0"),
        (2.0, 1.0, "far_clip 1 must be greater than near_clip 2"),
    ] {
        let lookat = r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#;
        let text = with_camera(lookat, "").replace("<film", &format!("{}<film", clip(near, far)));
        let e = xml("clip-bad.xml", &text, &[]).unwrap_err().to_string();
        assert!(e.contains(what) && e.contains("clip-bad.xml"), "{e}");
    }
    // TOML cameras take the same two settings (no clipping by default), with the same checks.
    let bad = [
        ("near_clip = -1", "near_clip -1 must be a finite distance, 0 or more"),
        ("near_clip = 2\nfar_clip = 2", "far_clip 2 must lie beyond near_clip 2"),
        // And the pixel filter, which TOML cameras name too.
        ("filter = { type = \"tent\", radius = 0 }", "tent radius 0 must be above 0"),
        ("filter = { type = \"gaussian\", stddev = 1e6 }", "at most 1024 pixels"),
        ("filter = { type = \"sinc\" }", "unknown variant `sinc`"),
        ("filter = { type = \"lanczos\", lobes = 64 }", "accepted 0.0"),
    ];
    for (clip, what) in bad {
        let text = format!(
            "[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [8, 8]\n{clip}\n"
        );
        let e = load_str(&temp_dir().join("clip.toml"), &text, &[]).unwrap_err().to_string();
        assert!(e.contains(what) && e.contains("clip.toml"), "{e}");
    }
}

/// `rayleigh` and `blendphase` read as Mitsuba renders them: a blend's two phases in the order
/// written, whatever their names; bad blends say what to do.
#[test]
fn rayleigh_and_blended_phase_functions() {
    use zerovar::phase::{Lobe, PhaseFunction};
    let medium = |phase: &str| {
        let body = format!(
            r#"<shape type="cube"><bsdf type="null"/><medium type="homogeneous" name="interior">{phase}</medium></shape>"#
        );
        let lookat = r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#;
        xml("phase.xml", &with_camera(lookat, &body), &[]).map(|s| s.media()[0].phase)
    };
    assert_eq!(medium(r#"<phase type="rayleigh"/>"#).unwrap(), PhaseFunction::Rayleigh);
    let named = r#"<phase type="blendphase"><float name="weight" value="0.25"/>
        <phase name="phase_1" type="hg"><float name="g" value="-0.3"/></phase>
        <phase name="phase_0" type="rayleigh"/></phase>"#;
    let expected = PhaseFunction::Blend {
        weight: 0.25,
        first: Lobe::HenyeyGreenstein { g: -0.3 },
        second: Lobe::Rayleigh,
    };
    assert_eq!(medium(named).unwrap(), expected);
    let unnamed = r#"<phase type="blendphase"><phase type="isotropic"/><phase type="hg"/></phase>"#;
    let expected = PhaseFunction::Blend {
        weight: 0.5,
        first: Lobe::Isotropic,
        second: Lobe::HenyeyGreenstein { g: 0.8 },
    };
    assert_eq!(medium(unnamed).unwrap(), expected);
    for (phase, says) in [
        (
            r#"<phase type="blendphase"><phase type="hg"/></phase>"#,
            "exactly two <phase> elements, not 1",
        ),
        (
            r#"<phase type="blendphase"><float name="weight" value="1.5"/><phase type="hg"/><phase type="hg"/></phase>"#,
            "blendphase weight 1.5 must lie in [0, 1]",
        ),
        (
            r#"<phase type="blendphase"><phase type="hg"/><phase type="blendphase"><phase type="hg"/><phase type="hg"/></phase></phase>"#,
            "a blendphase inside a blendphase is not supported",
        ),
        (r#"<phase type="lut"/>"#, "use isotropic, hg, rayleigh or blendphase"),
    ] {
        let e = medium(phase).unwrap_err().to_string();
        assert!(e.contains(says), "{phase}: {e}");
    }
    // TOML names the same phases.
    let toml = |phase: &str| {
        let text = format!(
            "[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [8, 8]\n\
             [media.fog]\ntype = \"homogeneous\"\nphase = {phase}\n"
        );
        load_str(&temp_dir().join("phase.toml"), &text, &[]).map(|s| s.media()[0].phase)
    };
    let blend = r#"{ type = "blendphase", weight = 0.2, phases = [{ type = "hg", g = 0.85 }, { type = "rayleigh" }] }"#;
    let expected = PhaseFunction::Blend {
        weight: 0.2,
        first: Lobe::HenyeyGreenstein { g: 0.85 },
        second: Lobe::Rayleigh,
    };
    assert_eq!(toml(blend).unwrap(), expected);
    let e = toml(r#"{ type = "rayleigh", g = 0.3 }"#).unwrap_err().to_string();
    assert!(e.contains("`g` does not apply to rayleigh phase functions"), "{e}");
    let e = toml(r#"{ type = "blendphase", phases = [{ type = "hg", g = 0.5 }] }"#).unwrap_err();
    assert!(e.to_string().contains("blendphase blends exactly two phases"), "{e}");
}

/// Mitsuba's other samplers place their samples differently but converge to the same image:
/// zerovar draws independent samples for each, with the sample count rounded as that sampler
/// rounds it. The expected counts are what Mitsuba 3.9.1's Python loader reports for each
/// requested one (`mi.load_dict({'type': t, 'sample_count': n}).sample_count()`).
#[test]
fn every_mitsuba_sampler_renders_its_rounded_sample_count() {
    let cases: [(&str, &[(u32, u32)]); 5] = [
        ("independent", &[(1, 1), (10, 10)]),
        ("stratified", &[(1, 1), (2, 4), (5, 9), (17, 25), (33, 36), (64, 64), (1000, 1024)]),
        (
            "multijitter",
            &[(1, 1), (3, 3), (5, 6), (7, 8), (10, 12), (17, 20), (33, 35), (1000, 1023)],
        ),
        ("orthogonal", &[(1, 4), (5, 9), (10, 25), (33, 49), (64, 121), (1000, 1369)]),
        ("ldsampler", &[(1, 4), (5, 16), (10, 16), (17, 64), (64, 64), (100, 256), (1000, 1024)]),
    ];
    for (kind, counts) in cases {
        for &(asked, rendered) in counts {
            let text = format!(
                "<scene version=\"3.0.0\">\n  <sensor type=\"perspective\">\n    <float \
                 name=\"fov\" value=\"40\"/>\n    <sampler type=\"{kind}\"><integer \
                 name=\"sample_count\" value=\"{asked}\"/></sampler>\n  </sensor>\n</scene>\n"
            );
            let s = xml("sampler.xml", &text, &[]).unwrap_or_else(|e| panic!("{kind}: {e}"));
            assert_eq!(s.settings().spp, rendered, "{kind}, {asked} asked");
        }
    }
    // Their own options are read (and a misspelt one is still an error).
    let text = "<scene version=\"3.0.0\">\n  <sensor type=\"perspective\">\n    <float \
                name=\"fov\" value=\"40\"/>\n    <sampler type=\"orthogonal\"><boolean \
                name=\"jitter\" value=\"false\"/><float name=\"strength\" value=\"2\"/>\
                </sampler>\n  </sensor>\n</scene>\n";
    assert!(xml("sampler.xml", text, &[]).is_ok());
    let e = xml("sampler.xml", &text.replace("strength", "strenght"), &[]).unwrap_err();
    assert!(e.to_string().contains("strenght"), "{e}");
    let e = xml("sampler.xml", &text.replace("orthogonal", "sobol"), &[]).unwrap_err();
    assert!(e.to_string().contains("`sobol` sampler is not supported"), "{e}");
}

/// A homogeneous medium as Mitsuba takes it: its albedo may be a constant volume (the same
/// image as the colour), `has_spectral_extinction` is a sampling hint, refused only where it
/// would make Mitsuba's own image wrong (false over a chromatic extinction), and an albedo grid
/// says what to use instead.
#[test]
fn homogeneous_media_take_mitsubas_albedo_volumes_and_extinction_hint() {
    let scene = |medium: &str| {
        format!(
            r#"<scene version="3.0.0">
            <integrator type="volpath"/>
            <sensor type="perspective">
                <float name="fov" value="40"/>
                <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
                <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
            </sensor>
            <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
            <shape type="sphere">
                <bsdf type="null"/>
                <medium type="homogeneous" name="interior">{medium}</medium>
            </shape>
        </scene>"#
        )
    };
    let colour =
        xml("albedo-colour.xml", &scene(r#"<rgb name="albedo" value="0.2, 0.5, 0.9"/>"#), &[])
            .unwrap_or_else(|e| panic!("{e}"));
    let volume = xml(
        "albedo-volume.xml",
        &scene(
            r#"<volume name="albedo" type="constvolume"><rgb name="value" value="0.2, 0.5, 0.9"/></volume>
               <boolean name="has_spectral_extinction" value="false"/>"#,
        ),
        &[],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(image(&colour, 3), image(&volume, 3));
    // The default albedo (Mitsuba's 0.75) differs, so the comparison above can fail.
    let default = xml("albedo-default.xml", &scene(""), &[]).unwrap();
    assert_ne!(image(&colour, 3), image(&default, 3));

    let hint = r#"<rgb name="sigma_t" value="1, 2, 3"/><boolean name="has_spectral_extinction" value="false"/>"#;
    let err = xml("hint.xml", &scene(hint), &[]).expect_err("refused").to_string();
    assert!(err.contains("hint.xml:") && err.contains("has_spectral_extinction"), "{err}");
    let hint = r#"<rgb name="sigma_t" value="1, 2, 3"/><boolean name="has_spectral_extinction" value="true"/>"#;
    xml("hint-true.xml", &scene(hint), &[]).unwrap_or_else(|e| panic!("{e}"));

    let grid = r#"<volume name="albedo" type="gridvolume"><string name="filename" value="a.vol"/></volume>"#;
    let err = xml("grid-albedo.xml", &scene(grid), &[]).expect_err("refused").to_string();
    assert!(err.contains("grid-albedo.xml:") && err.contains("heterogeneous"), "{err}");
}

/// Images as Mitsuba's bitmaps read them beyond PNG and OpenEXR: a JPEG texture decoded from
/// sRGB (unless `raw`), and a Radiance HDR environment map as stored (linear).
#[test]
fn jpeg_textures_and_radiance_hdr_environment_maps() {
    let grey = image::RgbImage::from_pixel(8, 8, image::Rgb([128, 128, 128]));
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 100).encode_image(&grey).unwrap();
    write("grey.jpg", &jpeg);
    for (raw, want) in
        [("false", ((128.0f32 / 255.0 + 0.055) / 1.055).powf(2.4)), ("true", 128.0 / 255.0)]
    {
        let text = sphere_with(&format!(
            "<bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">\
             <string name=\"filename\" value=\"grey.jpg\"/><boolean name=\"raw\" value=\"{raw}\"/>\
             </texture></bsdf>"
        ));
        let s = xml("jpeg.xml", &text, &[]).unwrap_or_else(|e| panic!("{e}"));
        let zerovar::bsdf::Bsdf::Diffuse { reflectance, .. } = &s.surfaces()[0].bsdf else {
            panic!("{:?}", s.surfaces()[0].bsdf)
        };
        let v = reflectance.eval(Vec2::new(0.5, 0.5)).to_array();
        assert!(v.iter().all(|c| (c - want).abs() < 0.01), "raw {raw}: {v:?} against {want}");
    }

    // A sky of 1.5 in its upper half and 0.25 in its lower one, as Radiance HDR (both exact
    // in its 8-bit mantissas).
    let pixels: Vec<image::Rgb<f32>> =
        (0..8 * 16).map(|i| image::Rgb([if i < 4 * 16 { 1.5 } else { 0.25 }; 3])).collect();
    let mut hdr = Vec::new();
    image::codecs::hdr::HdrEncoder::new(&mut hdr).encode(&pixels, 16, 8).unwrap();
    write("sky.hdr", &hdr);
    let env = |file: &str| {
        format!(
            r#"<scene version="3.0.0"><integrator type="volpath"/>
            <sensor type="perspective"><float name="fov" value="40"/></sensor>
            <emitter type="envmap"><string name="filename" value="{file}"/></emitter></scene>"#
        )
    };
    let s = xml("hdr-sky.xml", &env("sky.hdr"), &[]).unwrap_or_else(|e| panic!("{e}"));
    let up = s.lights()[0].eval_escaped(Vec3A::Y).0.to_array();
    let down = s.lights()[0].eval_escaped(-Vec3A::Y).0.to_array();
    assert_eq!((up, down), ([1.5; 3], [0.25; 3]));
    let e = xml("gif-sky.xml", &env("tex.gif"), &[]).unwrap_err().to_string();
    assert!(e.contains("gif-sky.xml:") && e.contains("Radiance HDR (.hdr)"), "{e}");
}

/// Shadow rays towards lights at infinity reach twice the larger of the scene's bounding radius
/// and the point's distance from its centre, where Mitsuba places such lights: spheres of
/// radius 1 at x = 0 and x = 4 span a box centred at x = 2 of half-diagonal sqrt(11).
#[test]
fn lights_at_infinity_are_twice_the_scenes_radius_away() {
    let s = crate::common::scene(
        "[camera]\norigin = [0, 0, 9]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [8, 8]\n\
         [[shapes]]\ntype = \"sphere\"\n[[shapes]]\ntype = \"sphere\"\ncenter = [4, 0, 0]\n",
    );
    let radius = 11.0f32.sqrt();
    let centre = Vec3A::new(2.0, 0.0, 0.0);
    assert!((s.infinite_reach(centre) - 2.0 * radius).abs() < 1e-4, "{}", s.infinite_reach(centre));
    let inside = Vec3A::new(2.5, 0.5, 0.0);
    assert!((s.infinite_reach(inside) - 2.0 * radius).abs() < 1e-4);
    let far = Vec3A::new(22.0, 0.0, 0.0);
    assert!((s.infinite_reach(far) - 40.0).abs() < 1e-4, "{}", s.infinite_reach(far));
}

/// Mitsuba's `thinlens` sensor (its aperture required, its focus the far plane by default),
/// spectra whose wavelength:value pairs are separated by spaces as Mitsuba's tokenizer allows,
/// and emitters' `sampling_weight`: equal weights accepted, unequal ones (which change
/// Mitsuba's image) an error naming the place.
#[test]
fn thin_lens_spaced_spectra_and_sampling_weights() {
    let scene = |sensor: &str, light: &str| {
        format!(
            "<scene version=\"3.0.0\"><sensor type={sensor}<float name=\"fov\" value=\"40\"/>\
             </sensor><shape type=\"sphere\"><bsdf type=\"diffuse\"/>{light}</shape>\
             <emitter type=\"constant\"><float name=\"sampling_weight\" value=\"2\"/></emitter></scene>"
        )
    };
    let area = |w: &str| {
        format!("<emitter type=\"area\"><float name=\"sampling_weight\" value=\"{w}\"/></emitter>")
    };
    let (lens, pinhole) =
        ("\"thinlens\"><float name=\"aperture_radius\" value=\"0.1\"/>", "\"perspective\">");
    let s = xml("lens.xml", &scene(lens, &area("2")), &[]).unwrap_or_else(|e| panic!("{e}"));
    assert!(s.camera().has_lens());
    // Mitsuba reads a focus distance on a pinhole too, and ignores it.
    let focused = "\"perspective\"><float name=\"focus_distance\" value=\"3\"/>";
    let s = xml("focus.xml", &scene(focused, &area("2")), &[]).unwrap_or_else(|e| panic!("{e}"));
    assert!(!s.camera().has_lens());
    let e = xml("lens-bad.xml", &scene("\"thinlens\">", ""), &[]).unwrap_err().to_string();
    assert!(e.contains("lens-bad.xml:1:") && e.contains("aperture_radius"), "{e}");
    let e = xml("weights.xml", &scene(pinhole, &area("3")), &[]).unwrap_err().to_string();
    assert!(e.contains("weights.xml:1:") && e.contains("sampling_weight differ"), "{e}");
    // A light without a weight weighs 1, which differs from 2.
    let e = xml("weights-2.xml", &scene(pinhole, "<emitter type=\"area\"/>"), &[]).unwrap_err();
    assert!(e.to_string().contains("sampling_weight differ"), "{e}");
    let spectrum = |sep: &str| {
        let value = ["400:0.1", "500:0.2", "600:0.8", "700:0.9"].join(sep);
        sphere_with(&format!(
            "<bsdf type=\"diffuse\"><spectrum name=\"reflectance\" value=\"{value}\"/></bsdf>"
        ))
    };
    let commas = xml("spectrum-commas.xml", &spectrum(", "), &[]).unwrap();
    let spaces = xml("spectrum-spaces.xml", &spectrum(" \n "), &[]).unwrap();
    assert_eq!(commas.surfaces()[0].bsdf, spaces.surfaces()[0].bsdf);
}
