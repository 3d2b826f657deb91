//! The measured medium in the files renderers read (`workbench export`): a Mitsuba 3 scene, pbrt-v4
//! scene text, a Blender Python snippet for the Principled BSDF and Unreal's Subsurface Profile
//! values. Each states its units. The medium is fit.json's `"medium"` (docs/formats.md): σa and
//! σs′ per channel with an isotropic phase function (so σs = σs′), η, and the boundary's GGX α.
//! What each renderer's parameters mean, and how they are mapped: docs/medium.md, "Exports".

use crate::formats::fit::MediumJson;
use std::fmt::Write;

/// The renderers `export` writes for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Target {
    /// Mitsuba 3 scene XML: a rough dielectric sphere around a homogeneous medium.
    Mitsuba,
    /// pbrt-v4 scene text: the same as named medium and material.
    Pbrt,
    /// Blender (bpy) Python: a Principled BSDF with random-walk subsurface scattering.
    Blender,
    /// Unreal Engine's Subsurface Profile (Burley) values, as JSON.
    Unreal,
}

impl Target {
    /// The file written into the output folder.
    pub fn file_name(self) -> &'static str {
        match self {
            Target::Mitsuba => "mitsuba.xml",
            Target::Pbrt => "pbrt.pbrt",
            Target::Blender => "blender.py",
            Target::Unreal => "unreal-subsurface-profile.json",
        }
    }

    /// The file's text for `medium`, with a sphere of `radius_mm` where the format takes a scene.
    pub fn text(self, medium: &MediumJson, radius_mm: f64) -> String {
        match self {
            Target::Mitsuba => mitsuba(medium, radius_mm),
            Target::Pbrt => pbrt(medium, radius_mm),
            Target::Blender => blender(medium),
            Target::Unreal => unreal(medium),
        }
    }
}

/// Three numbers as `a, b, c` (Mitsuba) or `a b c` (pbrt), shortest round-trip form.
fn three(v: [f64; 3], sep: &str) -> String {
    v.map(|x| format!("{x:?}")).join(sep)
}

/// Mitsuba 3: `roughdielectric` (GGX, α, int_ior η) around a `homogeneous` medium (σt, albedo,
/// isotropic phase), on a sphere. Mitsuba has no units: the scene is in millimetres, so σt is
/// per millimetre (`sigma_t` times `scale`).
fn mitsuba(m: &MediumJson, radius_mm: f64) -> String {
    let (t, albedo) = m.extinction_and_albedo();
    let mut s = String::new();
    let _ = writeln!(s, "<?xml version=\"1.0\" encoding=\"utf-8\"?>");
    let _ = writeln!(
        s,
        "<!-- workbench export: the measured medium (docs/medium.md). Units: millimetres; extinction = sigma_t times scale, in 1/mm. \
         Isotropic phase: sigma_s = sigma_s' of fit.json. Load with mitsuba.load_file(); add a sensor, emitter and volpath integrator to render. -->"
    );
    let _ = writeln!(s, "<scene version=\"3.0.0\">");
    let _ = writeln!(
        s,
        "    <bsdf type=\"roughdielectric\" id=\"workbench-boundary\">"
    );
    let _ = writeln!(s, "        <string name=\"distribution\" value=\"ggx\"/>");
    let _ = writeln!(
        s,
        "        <float name=\"alpha\" value=\"{:?}\"/>",
        m.alpha.max(1e-4)
    );
    let _ = writeln!(
        s,
        "        <float name=\"int_ior\" value=\"{:?}\"/>",
        m.eta.value
    );
    let _ = writeln!(s, "        <float name=\"ext_ior\" value=\"1.0\"/>");
    let _ = writeln!(s, "    </bsdf>");
    let _ = writeln!(
        s,
        "    <medium type=\"homogeneous\" id=\"workbench-medium\">"
    );
    let _ = writeln!(
        s,
        "        <rgb name=\"albedo\" value=\"{}\"/>",
        three(albedo, ", ")
    );
    // Mitsuba reads an `rgb` as a reflectance, refused outside [0, 1] (jade's σt is 2 /mm): the
    // extinction is written over its largest channel, that channel's value the medium's `scale`.
    let scale = t.iter().copied().fold(f64::MIN_POSITIVE, f64::max);
    let _ = writeln!(
        s,
        "        <rgb name=\"sigma_t\" value=\"{}\"/>",
        three(t.map(|v| v / scale), ", ")
    );
    let _ = writeln!(s, "        <float name=\"scale\" value=\"{scale:?}\"/>");
    let _ = writeln!(s, "        <phase type=\"isotropic\"/>");
    let _ = writeln!(s, "    </medium>");
    let _ = writeln!(s, "    <shape type=\"sphere\">");
    let _ = writeln!(
        s,
        "        <float name=\"radius\" value=\"{radius_mm:?}\"/>"
    );
    let _ = writeln!(s, "        <ref id=\"workbench-boundary\"/>");
    let _ = writeln!(
        s,
        "        <ref name=\"interior\" id=\"workbench-medium\"/>"
    );
    let _ = writeln!(s, "    </shape>");
    let _ = writeln!(s, "</scene>");
    s
}

/// pbrt-v4: a named `homogeneous` medium (σa, σs per channel, g = 0) inside a named `dielectric`
/// material (η, GGX roughness α without pbrt's remapping), on a sphere. pbrt has no units: the
/// scene is in millimetres.
fn pbrt(m: &MediumJson, radius_mm: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# workbench export: the measured medium (docs/medium.md). Units: millimetres; sigma_a, sigma_s in 1/mm."
    );
    let _ = writeln!(
        s,
        "# Isotropic phase (g = 0): sigma_s = sigma_s' of fit.json. Put the sphere inside WorldBegin with a camera, light and the volpath integrator."
    );
    let _ = writeln!(
        s,
        "MakeNamedMedium \"workbench-medium\" \"string type\" \"homogeneous\" \"rgb sigma_a\" [ {} ] \"rgb sigma_s\" [ {} ] \"float scale\" 1 \"float g\" 0",
        three(m.sigma_a_per_mm.value, " "),
        three(m.sigma_s_reduced_per_mm.value, " ")
    );
    let _ = writeln!(
        s,
        "MakeNamedMaterial \"workbench-boundary\" \"string type\" \"dielectric\" \"float eta\" {:?} \"float roughness\" {:?} \"bool remaproughness\" false",
        m.eta.value,
        m.alpha
    );
    let _ = writeln!(s, "AttributeBegin");
    let _ = writeln!(s, "    MediumInterface \"workbench-medium\" \"\"");
    let _ = writeln!(s, "    NamedMaterial \"workbench-boundary\"");
    let _ = writeln!(s, "    Shape \"sphere\" \"float radius\" {radius_mm:?}");
    let _ = writeln!(s, "AttributeEnd");
    s
}

/// Blender 4 (bpy): the active object's material as a Principled BSDF with random-walk
/// subsurface scattering: base colour the surface albedo, subsurface radius the transport mean
/// free path per channel (millimetres, scaled to metres by Subsurface Scale 0.001), IOR η,
/// roughness √α (Blender squares it).
fn blender(m: &MediumJson) -> String {
    let mfp = m.mean_free_path_mm.value;
    let a = m.diffuse_albedo.value;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# workbench export: the measured medium (docs/medium.md) as Blender's Principled BSDF."
    );
    let _ = writeln!(
        s,
        "# Units: Subsurface Radius in millimetres (the transport mean free path per channel), Subsurface Scale 0.001 turns it into metres (Blender's unit)."
    );
    let _ = writeln!(
        s,
        "# Run in Blender's Python console with the object selected."
    );
    let _ = writeln!(s, "import bpy");
    let _ = writeln!(s);
    let _ = writeln!(s, "obj = bpy.context.active_object");
    let _ = writeln!(s, "mat = bpy.data.materials.new(\"workbench-medium\")");
    let _ = writeln!(s, "mat.use_nodes = True");
    let _ = writeln!(s, "bsdf = mat.node_tree.nodes[\"Principled BSDF\"]");
    let _ = writeln!(s, "bsdf.subsurface_method = \"RANDOM_WALK\"");
    let _ = writeln!(
        s,
        "bsdf.inputs[\"Base Color\"].default_value = ({:?}, {:?}, {:?}, 1.0)",
        a[0], a[1], a[2]
    );
    let _ = writeln!(s, "bsdf.inputs[\"Subsurface Weight\"].default_value = 1.0");
    let _ = writeln!(
        s,
        "bsdf.inputs[\"Subsurface Radius\"].default_value = ({:?}, {:?}, {:?})",
        mfp[0], mfp[1], mfp[2]
    );
    let _ = writeln!(s, "bsdf.inputs[\"Subsurface Scale\"].default_value = 0.001");
    let _ = writeln!(s, "bsdf.inputs[\"IOR\"].default_value = {:?}", m.eta.value);
    let _ = writeln!(
        s,
        "bsdf.inputs[\"Roughness\"].default_value = {:?}",
        m.alpha.max(0.0).sqrt()
    );
    let _ = writeln!(s, "obj.data.materials.clear()");
    let _ = writeln!(s, "obj.data.materials.append(mat)");
    s
}

/// Unreal Engine's Subsurface Profile (Burley): surface albedo, the mean free path's colour (per
/// channel over the largest) and distance (centimetres, Unreal's unit), with the specular
/// roughness √α and the specular level F0/0.08 of η.
fn unreal(m: &MediumJson) -> String {
    let mfp = m.mean_free_path_mm.value;
    let largest = mfp.iter().copied().fold(f64::MIN, f64::max);
    let f0 = ((m.eta.value - 1.0) / (m.eta.value + 1.0)).powi(2);
    let v = serde_json::json!({
        "schema": "workbench.unreal-subsurface-profile/1",
        "units": "MeanFreePathDistance in centimetres (Unreal's unit); colours linear, not sRGB",
        "SurfaceAlbedo": m.diffuse_albedo.value,
        "MeanFreePathColor": mfp.map(|x| x / largest),
        "MeanFreePathDistance": largest / 10.0,
        "Roughness": m.alpha.max(0.0).sqrt(),
        "Specular": f0 / 0.08,
        "IOR": m.eta.value,
        "source": "workbench export: the transport mean free path 1/(σa + σs′) and the dipole's surface albedo of fit.json's medium (docs/medium.md)",
    });
    serde_json::to_string_pretty(&v).expect("a JSON value") + "\n"
}
