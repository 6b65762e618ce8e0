//! Any bytes as a PLY mesh: reading returns a mesh or an error, never panics, and never
//! allocates more than the input's size justifies (a header claiming 10^12 vertices fails).
#![no_main]

use libfuzzer_sys::fuzz_target;
use zerovar::shapes::Mesh;
use zerovar::transform::Transform;

fuzz_target!(|data: &[u8]| {
    let _ = Mesh::from_ply_bytes(data, &Transform::IDENTITY, false, false);
});
