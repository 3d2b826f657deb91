//! fit.json as `workbench plot` reads it: parse, validate, derive the parameters, and draw every
//! figure that needs no photo (the correlation matrix, the per-radius curves) as PNG pixels.
//! Must never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use workbench::formats::fit::FitFile;

fuzz_target!(|data: &[u8]| {
    if let Ok(f) = serde_json::from_slice::<FitFile>(data) {
        if f.validate(std::path::Path::new("fit.json")).is_ok() {
            let _ = f.params();
            for r in [1.0, 20.0] {
                let _ = f.params_for(r);
                if let Some(b) = &f.baseline {
                    let _ = b.params_for(r);
                }
            }
            for named in workbench::figures::fitplot::figures(&f, &[]) {
                let _ = named.figure.to_rgb();
            }
        }
    }
});
