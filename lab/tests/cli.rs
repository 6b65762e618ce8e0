//! The `zerovar` command on good and bad input: bad input must exit non-zero with an error
//! naming the file and the place, and never panic.

use std::path::Path;
use std::process::{Command, Output};
use zerovar_testkit::files::{repo, temp_dir, write};

fn zerovar(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_zerovar")).args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `check` and `render` on `scene` and expects both to fail with every `needle` in the
/// message.
fn assert_fails(scene: &Path, needles: &[&str]) {
    let out = temp_dir().join("bad.exr");
    for args in [
        vec!["check", scene.to_str().unwrap()],
        vec![
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--quiet",
            "--spp",
            "1",
        ],
    ] {
        let o = zerovar(&args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: `{n}` missing from: {err}");
        }
    }
}

const GOOD: &str = r#"
[defaults]
g = 0.2

[camera]
origin = [0, 0, 4]
target = [0, 0, 0]
fov = 30
resolution = [8, 6]

[media.cloud]
type = "grid"
density = "cloud.vol"
scale = 2
phase = { type = "hg", g = "$g" }

[[shapes]]
type = "cube"
bsdf = { type = "null" }
interior = "cloud"

[[lights]]
type = "directional"
direction = [0, -1, 0]
irradiance = 1
"#;

/// A 2x2x1 `.vol` file, written byte by byte so that it may hold values no `VolGrid` accepts.
fn vol(values: &[f32]) -> Vec<u8> {
    let mut b = b"VOL\x03".to_vec();
    for i in [1i32, 2, 2, 1, 1] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    for v in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0].iter().chain(values) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}

#[test]
fn renders_a_scene_with_outputs_and_stats() {
    write("cloud.vol", vol(&[0.5, 1.0, 0.2, 0.0]));
    let scene = write("good.toml", GOOD);
    let dir = temp_dir();
    let exr = dir.join("good.exr");
    let stats = dir.join("good.json");
    let o = zerovar(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        exr.to_str().unwrap(),
        "--spp",
        "2",
        "--threads",
        "2",
        "-D",
        "g=0.7",
        "--stats",
        stats.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(exr.is_file() && dir.join("good.png").is_file());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(json["spp"], 2);
    assert_eq!(json["invalid_samples"], 0);
    assert!(json["paths_per_second"].as_f64().unwrap() > 0.0);
    let o = zerovar(&["check", scene.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && out.contains("delta tracking"), "{out}");
    // Measured trackers: a table per heterogeneous medium; a budget of 0 is refused.
    let o = zerovar(&["check", repo("scenes/cloud.toml").to_str().unwrap(), "--trackers", "0.2"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && out.contains("trackers on `cloud`"), "{out}");
    assert!(out.contains("weighted-decomposition"), "{out}");
    let o = zerovar(&["check", repo("scenes/cloud.toml").to_str().unwrap(), "--trackers", "0"]);
    assert!(!o.status.success() && stderr(&o).contains("--trackers 0"), "{}", stderr(&o));
    // The README's first command works as written.
    let o = zerovar(&["check", repo("scenes/fog-sphere.toml").to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `check --trackers` on a grid of constant density: decomposition's control carries every
/// collision, so it makes no lookup, and residual ratio tracking's shadow rays are exact, so
/// its renders vary less than delta tracking's: 2.4x less at 65 spp, so the check holds at
/// whatever spp the machine's speed gives the budget (the efficiencies, timed, are not
/// checked).
#[test]
fn measured_trackers_find_decomposition_exact_in_a_constant_grid() {
    write("constant.vol", vol(&[1.0, 1.0, 1.0, 1.0]));
    let text = GOOD
        .replace("cloud.vol", "constant.vol")
        .replace("resolution = [8, 6]", "resolution = [48, 36]")
        .replace("scale = 2", "scale = 6");
    let scene = write("constant.toml", &text);
    let o = zerovar(&["check", scene.to_str().unwrap(), "--trackers", "1"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    let variance_and_lookups = |name: &str| -> (f64, f64) {
        let line = out
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("no {name} in {out}"));
        let after = |key: &str| -> f64 {
            let rest = &line[line.find(key).unwrap_or_else(|| panic!("{line}")) + key.len()..];
            rest.trim_start().split([' ', ',']).next().unwrap().parse().unwrap()
        };
        let lookups = line.split(" s per render, ").nth(1).unwrap();
        (after("relative variance"), lookups.split(' ').next().unwrap().parse().unwrap())
    };
    let (delta, delta_lookups) = variance_and_lookups("delta");
    let (decomposition, lookups) = variance_and_lookups("decomposition");
    assert!(delta_lookups > 1.0 && lookups == 0.0, "{out}");
    assert!(decomposition < 0.95 * delta, "{out}");
}

#[test]
fn bad_scenes_fail_clearly() {
    write("cloud.vol", vol(&[0.5, 1.0, 0.2, 0.0]));
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        ("malformed.toml", GOOD.replace("[camera]", "[camera"), vec!["malformed.toml:5:"]),
        (
            "unknown.toml",
            GOOD.replace("fov = 30", "fov = 30\nfocal = 2"),
            vec!["unknown.toml:9:", "focal"],
        ),
        (
            "missing.toml",
            GOOD.replace("cloud.vol", "nowhere.vol"),
            vec!["missing.toml:11:", "media.cloud", "nowhere.vol"],
        ),
        (
            "zerodir.toml",
            GOOD.replace("[0, -1, 0]", "[0, 0, 0]"),
            vec!["zerodir.toml:22:", "lights[0]", "zero length"],
        ),
        (
            "negsigma.toml",
            GOOD.replace("scale = 2", "scale = -2"),
            vec!["negsigma.toml:11:", "scale -2"],
        ),
        (
            "badg.toml",
            GOOD.replace("g = 0.2", "g = 1.0"),
            vec!["badg.toml:11:", "strictly between -1 and 1"],
        ),
        (
            "devzero.toml",
            GOOD.replace("cloud.vol", "/dev/zero"),
            vec!["devzero.toml:11:", "/dev/zero", "not a regular file"],
        ),
        (
            "huge.toml",
            GOOD.replace("resolution = [8, 6]", "resolution = [32768, 32768]"),
            vec!["huge.toml:", "1073741824 pixels, more than 33554432", "lower the resolution"],
        ),
        (
            "wide.toml",
            GOOD.replace("resolution = [8, 6]", "resolution = [40000, 1]"),
            vec!["wide.toml:", "between 1 and 32768 pixels per axis"],
        ),
        (
            "wrapped.toml",
            GOOD.replace("resolution = [8, 6]", "resolution = [4294967312, 6]"),
            vec!["wrapped.toml:", "[4294967312, 6] must be between 1 and 32768"],
        ),
        (
            "far.toml",
            GOOD.replace("origin = [0, 0, 4]", "origin = [1e20, 0, 4]"),
            vec!["far.toml:", "[1e20, 0.0, 4.0] lies beyond +-1e15", "nearer the origin"],
        ),
        (
            "twocolour.toml",
            GOOD.replace("irradiance = 1", "irradiance = [1, 2]"),
            vec!["twocolour.toml:", "a colour has three channels [r, g, b]", "not 2"],
        ),
        (
            "textcolour.toml",
            GOOD.replace("irradiance = 1", "irradiance = \"bright\""),
            vec!["textcolour.toml:", "\"bright\"", "one number, or three in brackets"],
        ),
    ];
    for (name, text, needles) in cases {
        assert_fails(&write(name, text), &needles);
    }
}

#[test]
fn bad_volume_files_fail_clearly() {
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("truncated.vol", vol(&[0.5, 1.0, 0.2, 0.0])[..60].to_vec(), "truncated"),
        ("negative.vol", vol(&[0.5, -1.0, 0.2, 0.0]), "voxel (1, 0, 0)"),
        ("nan.vol", vol(&[0.5, 1.0, f32::NAN, 0.0]), "voxel (0, 1, 0)"),
        (
            "garbage.vol",
            b"not a volume at all, just some text padding it out to 48 bytes...".to_vec(),
            "VOL",
        ),
    ];
    for (name, bytes, needle) in cases {
        write(name, bytes);
        let scene = write(&format!("{name}.toml"), GOOD.replace("cloud.vol", name));
        assert_fails(&scene, &[name, needle, "media.cloud"]);
    }
    // A density times its scale beyond single precision would give an infinite majorant.
    write("dense.vol", vol(&[0.5, 4.0, 0.2, 0.0]));
    let scene = write(
        "dense.toml",
        GOOD.replace("cloud.vol", "dense.vol").replace("scale = 2", "scale = 1e38"),
    );
    assert_fails(
        &scene,
        &["dense.toml", "media.cloud", "largest density 4 times the extinction", "overflows"],
    );
}

#[test]
fn bad_arguments_fail_clearly() {
    let scene = repo("scenes/fog-sphere.toml");
    let s = scene.to_str().unwrap();
    for (args, needle) in [
        (vec!["render", s, "--spp", "0"], "--spp 0"),
        (vec!["render", s, "--time", "-1"], "--time"),
        (vec!["render", s, "-o", "x.png"], ".exr"),
        (vec!["render", s, "-D", "nosuch=1"], "nosuch"),
        (vec!["render", s, "-D", "novalue"], "KEY=VALUE"),
        (vec!["render", "/nonexistent/scene.toml"], "/nonexistent/scene.toml"),
        (vec!["render", "/dev/zero"], "not a regular file"),
        (vec!["render", s, "--training-images", "keep"], "give combine or discard"),
        (vec!["render", s, "--exposure", "128"], "from -64 to 64"),
        (vec!["render", s, "--threads", "100000"], "give at most 1024"),
        (vec!["render", s, "--time", "1e12"], "below 1e7"),
    ] {
        let o = zerovar(&args);
        let err = stderr(&o);
        assert!(
            !o.status.success() && err.contains(needle) && !err.contains("panicked"),
            "{args:?}: {err}"
        );
        // Said once: a library error that quotes its cause is not followed by it again.
        assert_eq!(err.matches(needle).count(), 1, "{args:?} repeats itself: {err}");
    }
    // A reference's default budget, 16 times the scene's spp, past 2^32: refused, not wrapped
    // to a few samples.
    write("cloud.vol", vol(&[0.5, 1.0, 0.2, 0.0]));
    let many = write("many-spp.toml", format!("{GOOD}\n[render]\nspp = 268435457\n"));
    let out = temp_dir().join("many-spp.exr");
    let o = zerovar(&["reference", many.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(
        !o.status.success() && stderr(&o).contains("more than can be counted"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
    // A named pipe as the scene: an error at once, not a read that blocks.
    let fifo = temp_dir().join("scene-fifo.toml");
    let _ = std::fs::remove_file(&fifo);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        let o = zerovar(&["check", fifo.to_str().unwrap()]);
        assert!(!o.status.success() && stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    }
}

#[test]
fn trains_a_field_and_renders_with_it() {
    write("cloud.vol", vol(&[0.5, 1.0, 0.2, 0.0]));
    let scene = write("train.toml", GOOD);
    let dir = temp_dir();
    let field = dir.join("train.zvg");
    let s = scene.to_str().unwrap();
    let o = zerovar(&["train", s, "-o", field.to_str().unwrap(), "--train-passes", "3", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(field.is_file());
    // The parallax setting is the field's, saved with it.
    let flat = dir.join("train-flat.zvg");
    let o = zerovar(&[
        "train",
        s,
        "-o",
        flat.to_str().unwrap(),
        "--train-passes",
        "2",
        "--parallax",
        "off",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let load = |p: &Path| zerovar::TrainedField::load(std::fs::File::open(p).unwrap()).unwrap();
    assert!(load(&field).field.config().parallax && !load(&flat).field.config().parallax);
    let exr = dir.join("train.exr");
    let stats = dir.join("train.json");
    let (e, f, st) = (exr.to_str().unwrap(), field.to_str().unwrap(), stats.to_str().unwrap());
    let o = zerovar(&["render", s, "-o", e, "--spp", "2", "--field", f, "--stats", st, "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = zerovar(&[
        "render",
        s,
        "-o",
        e,
        "--spp",
        "2",
        "--guiding",
        "full",
        "--train-passes",
        "2",
        "--stats",
        st,
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(json["training"]["passes"], 2);
    assert!(json["training"]["regions"].as_u64().unwrap() >= 1);
    // Adaptive guiding says what its training and its pilot did.
    let o = zerovar(&[
        "render",
        s,
        "-o",
        e,
        "--spp",
        "2",
        "--guiding",
        "auto",
        "--train-passes",
        "3",
        "--quiet",
    ]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("trained") && err.contains("adaptive guiding"), "{err}");
    // A file that is not a field, and bad guiding arguments, fail clearly.
    let bogus = write("bogus.zvg", b"not a field");
    let o = zerovar(&["render", s, "-o", e, "--field", bogus.to_str().unwrap(), "--quiet"]);
    assert!(
        !o.status.success() && stderr(&o).contains("bogus.zvg") && !stderr(&o).contains("panicked"),
        "{}",
        stderr(&o)
    );
    for (args, needle) in [
        (vec!["--guiding", "sideways"], "--guiding `sideways`: give off, directions"),
        (vec!["--guiding", "full", "--alpha", "1.5"], "--alpha 1.5: give a probability"),
        (vec!["--guiding", "full", "--alpha", "0.9"], "in [0, 0.8] (standard sampling keeps"),
        (
            vec!["--guiding", "directions+rr", "--alpha", "0", "--surface-alpha", "0"],
            "directions are guided at alpha 0 and surface-alpha 0, so none would be",
        ),
        (vec!["--guiding", "distances", "--alpha", "0"], "distances are guided at alpha 0"),
        (vec!["--train-share", "0.2", "--train-passes", "3"], "cannot be used with"),
        (vec!["--guiding", "full", "--distance-alpha", "2"], "--distance-alpha 2"),
        (vec!["--guiding", "full", "--train-passes", "0"], "--train-passes 0"),
        // A field with nothing to guide would be loaded for nothing.
        (vec!["--guiding", "off", "--field", f], "--guiding off: rendering with --field"),
        // A saved field keeps the lobes it was trained with.
        (vec!["--field", f, "--parallax", "off"], "--parallax: a saved field keeps"),
        (
            vec!["--guiding", "full", "--parallax", "sideways"],
            "--parallax `sideways`: give on or off",
        ),
        // With a saved field nothing trains.
        (
            vec!["--field", f, "--train-passes", "3"],
            "--train-passes: rendering with --field trains nothing",
        ),
        (vec!["--field", f, "--train-share", "0.5"], "--train-share: rendering with --field"),
        (vec!["--field", f, "--training-images", "discard"], "--training-images: rendering with"),
    ] {
        let o = zerovar(&[&["render", s, "-o", e, "--quiet"][..], &args].concat());
        assert!(!o.status.success() && stderr(&o).contains(needle), "{args:?}: {}", stderr(&o));
    }
    // A field with data appended, or trained on another scene, is refused.
    let mut bytes = std::fs::read(&field).unwrap();
    bytes.extend_from_slice(b"garbage");
    let appended = write("appended.zvg", bytes);
    let other = write(
        "other.toml",
        GOOD.replace("type = \"cube\"\n", "type = \"cube\"\ntransform = [{ scale = 2 }]\n"),
    );
    assert_ne!(std::fs::read_to_string(&other).unwrap(), GOOD, "the other scene is the same");
    for (scene, field, needles) in [
        (s, appended.to_str().unwrap(), ["appended.zvg", "data after the end"]),
        (other.to_str().unwrap(), f, ["--field", "trained on a scene with bounds"]),
    ] {
        let o = zerovar(&["render", scene, "-o", e, "--spp", "2", "--field", field, "--quiet"]);
        let err = stderr(&o);
        assert!(!o.status.success() && needles.iter().all(|n| err.contains(n)), "{err}");
    }
}

#[test]
fn reference_and_compare_end_to_end() {
    write("cloud.vol", vol(&[0.5, 1.0, 0.2, 0.0]));
    let scene = write("cmp.toml", GOOD);
    let s = scene.to_str().unwrap();
    let dir = temp_dir().join("cmp");
    let reference = temp_dir().join("cmp-ref.exr");
    let r = reference.to_str().unwrap();
    let o = zerovar(&["reference", s, "-o", r, "--spp", "64", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let d = dir.to_str().unwrap();
    let o = zerovar(&[
        "compare",
        s,
        "--reference",
        r,
        "--spp",
        "8",
        "--out",
        d,
        "--method",
        "a=guiding:off",
        "--method",
        "b=guiding:off",
        "--method",
        "g=guiding:full,alpha:0.5,train-passes:2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "results.md",
        "results.csv",
        "results.json",
        "a.exr",
        "a.png",
        "a-error.png",
        "g.exr",
        "strip.png",
        "crops.png",
        "convergence.png",
        "convergence.svg",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    // The plot names every method in its legend.
    let svg = std::fs::read_to_string(dir.join("convergence.svg")).unwrap();
    let texts: Vec<&str> =
        svg.split("</text>").filter_map(|t| t.rsplit('>').next()).map(str::trim).collect();
    for name in ["a", "b", "g", "relMSE"] {
        assert!(texts.contains(&name), "convergence.svg lacks the label {name}: {texts:?}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    let (a, b) = (&json[0], &json[1]);
    assert_eq!(a["checkpoints"].as_array().unwrap().len(), 4);
    // Three seeds by default, from the scene's seed on; the first seed's run is the
    // convergence curve's last point.
    let runs = a["runs"].as_array().unwrap();
    let seeds: Vec<u64> = runs.iter().map(|r| r["seed"].as_u64().unwrap()).collect();
    assert_eq!(seeds.len(), 3);
    assert!(seeds.windows(2).all(|w| w[1] == w[0] + 1), "{seeds:?}");
    assert_eq!(runs[0]["error"], a["checkpoints"][3]["error"]);
    // The same method twice: the same images, so the same errors; the speed-up is a timing
    // ratio.
    for (ra, rb) in runs.iter().zip(b["runs"].as_array().unwrap()) {
        assert_eq!(ra["error"]["rel_mse"]["all"], rb["error"]["rel_mse"]["all"]);
        // Leaving pixels out lowers the error.
        let trimmed = ra["trimmed"]["rel_mse"]["all"].as_f64().unwrap();
        assert!(trimmed <= ra["error"]["rel_mse"]["all"].as_f64().unwrap());
    }
    let speedup = b["speedup"].as_f64().unwrap();
    assert!(speedup > 0.25 && speedup < 4.0, "self speed-up {speedup}");
    // The reference carries its standard error: its share is reported and taken out.
    let mut used = Vec::new();
    let basis = a["error_basis"].as_str().unwrap();
    for run in runs {
        let e = &run["error"];
        let share = e["reference_noise"]["share"]["all"].as_f64().unwrap();
        let excess = e["reference_noise"]["excess"]["all"].as_f64().unwrap();
        let rel_mse = e["rel_mse"]["all"].as_f64().unwrap();
        assert!(share > 0.0 && (rel_mse - share - excess).abs() <= 1e-12 * rel_mse, "{e}");
        used.push(if basis == "excess" { excess } else { rel_mse });
    }
    // The efficiency's error is the runs' median.
    used.sort_by(f64::total_cmp);
    assert_eq!(a["error"].as_f64().unwrap(), used[1], "{basis}");
    assert!(a["rel_mse"]["min"].as_f64().unwrap() <= a["rel_mse"]["max"].as_f64().unwrap());
    let table = String::from_utf8_lossy(&o.stdout);
    assert_eq!(table.lines().count(), 8, "{table}");
    assert!(table.lines().take(5).skip(2).all(|l| l.split('|').count() == 12), "{table}");
    assert!(table.contains("Medians over 3 seeds"), "{table}");
    assert!(table.contains("The reference's own noise adds"), "{table}");
    // A reference without a standard-error layer (a render's EXR) keeps the raw relMSE, and
    // says so.
    let plain = dir.join("g.exr");
    let o = zerovar(&[
        "compare",
        s,
        "--reference",
        plain.to_str().unwrap(),
        "--spp",
        "2",
        "--out",
        temp_dir().join("cmp-plain").to_str().unwrap(),
        "--method",
        "a",
    ]);
    assert!(o.status.success() && stderr(&o).contains("has no `stderr` layer"), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(!table.contains("reference noise"), "{table}");
    // Errors: a reference of another size, a missing one, an unknown option.
    let small = write("cmp-small.toml", GOOD.replace("resolution = [8, 6]", "resolution = [4, 3]"));
    let o =
        zerovar(&["compare", small.to_str().unwrap(), "--reference", r, "--spp", "1", "--out", d]);
    assert!(
        !o.status.success() && stderr(&o).contains("8x6") && stderr(&o).contains("4x3"),
        "{}",
        stderr(&o)
    );
    for bad in ["6,0,4,4", "0,0,0,2", "1,2,3", "a,b,c,d"] {
        let o = zerovar(&["compare", s, "--reference", r, "--spp", "1", "--out", d, "--crop", bad]);
        assert!(
            !o.status.success() && stderr(&o).contains(&format!("--crop {bad}")),
            "{bad}: {}",
            stderr(&o)
        );
    }
    let o =
        zerovar(&["compare", s, "--reference", "/nonexistent/ref.exr", "--spp", "1", "--out", d]);
    assert!(!o.status.success() && stderr(&o).contains("/nonexistent/ref.exr"), "{}", stderr(&o));
    let o = zerovar(&[
        "compare",
        s,
        "--reference",
        r,
        "--spp",
        "1",
        "--out",
        d,
        "--method",
        "x=speed:11",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("unknown setting `speed`"),
        "{}",
        stderr(&o)
    );
    assert!(!stderr(&o).contains("panicked"));
}

/// The smallest valid Mitsuba scene (shared with `tests/xml.rs`), edited into bad ones.
const GOOD_XML: &str = include_str!("../../tests/data/minimal.xml");

#[test]
fn cli_checks_and_renders_xml_and_fails_cleanly() {
    let run =
        |args: &[&str]| Command::new(env!("CARGO_BIN_EXE_zerovar")).args(args).output().unwrap();
    let scene = repo("scenes/xml/fog-sphere.xml");
    let o = run(&["check", scene.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("fog          homogeneous"));
    let out = temp_dir().join("fog-xml.exr");
    let o = run(&[
        "render",
        repo("scenes/xml/cloud.xml").to_str().unwrap(),
        "--spp",
        "1",
        "-D",
        "density=2",
        "-o",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success() && out.is_file(), "{}", String::from_utf8_lossy(&o.stderr));

    let bad =
        write("bad-cli.xml", GOOD_XML.replace("<float name=\"radius\"", "<float nam=\"radius\""));
    for cmd in ["check", "render"] {
        let o = run(&[cmd, bad.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(!err.contains("panicked") && err.contains("bad-cli.xml:6:9"), "{err}");
        assert!(err.contains("<float> has no attribute `nam`"), "{err}");
    }
}

/// No output may replace an input or another output: each case fails before any work and
/// leaves the input as it was.
#[test]
fn outputs_never_replace_inputs() {
    write("keep.vol", vol(&[0.5, 1.0, 0.2, 0.0]));
    let scene = write("keep.toml", GOOD.replace("cloud.vol", "keep.vol"));
    let s = scene.to_str().unwrap();
    let before = std::fs::read(&scene).unwrap();
    let reference = temp_dir().join("keep-ref.exr");
    let r = reference.to_str().unwrap();
    let o = zerovar(&["reference", s, "-o", r, "--spp", "4", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let reference_before = std::fs::read(&reference).unwrap();
    let dir = temp_dir();
    let d = dir.to_str().unwrap();
    let here = dir.join("keep.exr");
    let e = here.to_str().unwrap();
    let stats_on_png = dir.join("keep.png");
    for (args, needle) in [
        (vec!["render", s, "-o", e, "--stats", s, "--quiet"], "--stats"),
        (
            vec!["render", s, "-o", e, "--stats", stats_on_png.to_str().unwrap()],
            "written there too",
        ),
        (vec!["train", s, "-o", s, "--quiet"], "-o"),
        (
            vec!["reference", s, "-o", r.replace("keep-ref.exr", "keep.toml").as_str(), "--quiet"],
            ".exr",
        ),
        (
            vec!["compare", s, "--reference", r, "--out", d, "--method", "keep-ref"],
            "the keep-ref.exr of --out",
        ),
        (
            vec![
                "compare",
                s,
                "--reference",
                r,
                "--out",
                d,
                "--method",
                "a",
                "--method",
                "a-error",
            ],
            "written there too",
        ),
    ] {
        let o = zerovar(&args);
        let err = stderr(&o);
        assert!(
            !o.status.success() && err.contains(needle) && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
    assert_eq!(std::fs::read(&scene).unwrap(), before, "the scene was replaced");
    assert_eq!(std::fs::read(&reference).unwrap(), reference_before, "the reference was replaced");
}

/// An output that cannot be written fails before any work, naming the flag and the reason,
/// and a render leaves no partial or temporary file beside its outputs.
#[test]
fn unwritable_outputs_fail_before_any_work() {
    let scene = write("writable.toml", GOOD.replace("cloud.vol", "writable.vol"));
    write("writable.vol", vol(&[0.5, 1.0, 0.2, 0.0]));
    let s = scene.to_str().unwrap();
    let dir = temp_dir().join("writable-out");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("a-directory.json")).unwrap();
    let missing = temp_dir().join("no-such-directory");
    let at = |p: &std::path::Path, f: &str| p.join(f).to_str().unwrap().to_string();
    let out = at(&dir, "out.exr");
    for (args, needles) in [
        (
            vec!["render", s, "-o", &at(&missing, "x.exr"), "--spp", "512"],
            vec!["-o", "no-such-directory", "does not exist"],
        ),
        (
            vec!["render", s, "-o", &out, "--stats", &at(&missing, "s.json"), "--spp", "512"],
            vec!["--stats", "does not exist"],
        ),
        (
            vec!["render", s, "-o", &out, "--stats", &at(&dir, "a-directory.json"), "--spp", "512"],
            vec!["--stats", "a directory"],
        ),
        (vec!["train", s, "-o", &at(&missing, "f.field")], vec!["-o", "does not exist"]),
        (
            vec!["reference", s, "-o", &at(&missing, "r.exr"), "--spp", "512"],
            vec!["-o", "does not exist"],
        ),
    ] {
        let o = zerovar(&args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {n} not in {err}");
        }
        // A render that ran before failing would have written its image.
        assert!(!dir.join("out.exr").exists(), "{args:?} rendered before failing");
    }
    let o = zerovar(&["render", s, "-o", &out, "--spp", "2", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["a-directory.json", "out.exr", "out.png"]);
}
