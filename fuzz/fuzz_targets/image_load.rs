//! Photo decoding as every command does it (PNG, JPEG, TIFF; EXIF; the size limits), from a file
//! in memory-backed /dev/shm. Must never panic, and never allocate beyond the 64 MP limit.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("workbench-fuzz-{}.img", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        let _ = workbench::formats::photo::load_linear_rgb(&path, None);
        let _ = workbench::formats::photo::ExifInfo::read(&path);
    }
});
