//! Any text as a Mitsuba XML scene: loading returns a scene or an error, never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = zerovar::scene::load_str(std::path::Path::new("fuzz.xml"), text, &[]);
    }
});
