//! Any bytes as an EXR (an environment map or a `--reference`): reading returns an image or an
//! error, never panics, and refuses a header claiming more pixels than zerovar reads before
//! allocating for them.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = zerovar::output::parse_exr(data);
});
