//! Any bytes as a `.vol` grid: parsing returns a grid or an error, never panics, and refuses
//! a header promising more data than there is before allocating for it.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = zerovar::media::VolGrid::parse(std::path::Path::new("fuzz.vol"), data);
});
