//! Any bytes as a Mitsuba `.serialized` file, its first and second mesh: reading returns a
//! mesh or an error, never panics, and never allocates more than the stream holds.
#![no_main]

use libfuzzer_sys::fuzz_target;
use zerovar::shapes::Mesh;
use zerovar::transform::Transform;

fuzz_target!(|data: &[u8]| {
    for index in [0, 1] {
        let _ = Mesh::from_serialized_bytes(data, index, &Transform::IDENTITY, false);
    }
});
