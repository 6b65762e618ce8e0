//! Any bytes as an OpenVDB file: parsing returns a grid or an error, never panics, and refuses
//! sizes the bytes cannot back (lengths, offsets, dense boxes) before allocating for them.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = zerovar::media::VdbGrid::parse(std::path::Path::new("fuzz.vdb"), data, None);
});
