//! OBJ and PLY meshes as `workbench render` reads them (the first byte picks the format): load with
//! its bounds, then the per-vertex curvature the renderer shades with. Must never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&kind, rest)) = data.split_first() else {
        return;
    };
    let ext = if kind % 2 == 0 { "obj" } else { "ply" };
    let path = std::env::temp_dir().join(format!("workbench-fuzz-{}.{ext}", std::process::id()));
    if std::fs::write(&path, rest).is_err() {
        return;
    }
    if let Ok(m) = workbench::render::mesh::Mesh::load(&path, workbench::render::mesh::Unit::Mm) {
        let _ = m.bounds();
        let _ = m.curvature();
    }
});
