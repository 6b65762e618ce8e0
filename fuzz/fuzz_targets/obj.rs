//! Any bytes as an OBJ mesh: reading returns a mesh or an error, never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;
use zerovar::shapes::Mesh;
use zerovar::transform::Transform;

fuzz_target!(|data: &[u8]| {
    // tobj reads from a path; each fuzzing process keeps one file of its own.
    let path = std::env::temp_dir().join(format!("zerovar-fuzz-{}.obj", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        let _ = Mesh::from_obj(&path, &Transform::IDENTITY, false, true);
    }
});
