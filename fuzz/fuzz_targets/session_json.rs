//! session.json as read by every command: parse, then validate. Must never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use workbench::formats::session::Session;

fuzz_target!(|data: &[u8]| {
    if let Ok(s) = serde_json::from_slice::<Session>(data) {
        let _ = s.validate(std::path::Path::new("session.json"));
    }
});
