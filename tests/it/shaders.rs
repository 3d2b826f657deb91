//! The shading snippets `lut --preset` writes, compiled by reference front ends inside a minimal
//! fragment shader that calls every function: GLSL ES 3.00 (WebGL2) and GLSL 3.30 by Khronos'
//! glslangValidator, HLSL by glslangValidator's HLSL front end (to SPIR-V), WGSL by naga's parser
//! and validator. A snippet with a syntax or type error fails here; the browser test
//! (tests/it/view.rs) checks the GLSL's numbers against `workbench render`.

use std::process::Command;
use workbench::render::preset::{GLSL, HLSL, WGSL};

fn glslang() -> Option<&'static str> {
    crate::common::system_tool("glslangValidator", "glslang-tools")
}

/// Compile `source` (written to a file named `name`) with glslangValidator and `args`; panics
/// with the compiler's output on an error.
fn compile(tool: &str, name: &str, source: &str, args: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, source).unwrap();
    let out = Command::new(tool)
        .args(args)
        .arg(&path)
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{name}:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

const GLSL_MAIN: &str = r#"
uniform sampler2D u_table;
in vec3 v_normal;
in vec3 v_position;
in float v_kappa;
out vec4 color;
void main() {
    vec3 n = normalize(v_normal);
    float kappa = v_kappa > 0.0 ? v_kappa : cdrf_screen_curvature(n, v_position);
    vec3 l = normalize(vec3(0.3, 0.4, 0.8));
    color = vec4(cdrf_radiance(u_table, n, l, vec3(0.0, 0.0, 1.0), kappa, vec2(0.0, 200.0),
                               1.0, 1.4, 0.5, 0.2), 1.0);
}
"#;

#[test]
fn glsl_compiles_for_webgl2_and_desktop() {
    let Some(tool) = glslang() else { return };
    for header in [
        "#version 300 es\nprecision highp float;\n",
        "#version 330 core\n",
    ] {
        compile(
            tool,
            "cdrf.frag",
            &format!("{header}{GLSL}{GLSL_MAIN}"),
            &[],
        );
    }
    // The check can fail: a snippet with a missing semicolon is refused.
    let broken = GLSL.replacen("return 1.0;", "return 1.0", 1);
    let r = std::panic::catch_unwind(|| {
        compile(
            tool,
            "cdrf.frag",
            &format!("#version 300 es\nprecision highp float;\n{broken}{GLSL_MAIN}"),
            &[],
        )
    });
    assert!(r.is_err(), "a broken snippet compiled");
}

#[test]
fn hlsl_compiles_to_spirv() {
    let Some(tool) = glslang() else { return };
    let main = r#"
Texture2D u_table : register(t0);
SamplerState u_sampler : register(s0);
float4 main(float3 n : NORMAL, float3 p : TEXCOORD1, float k : TEXCOORD0) : SV_Target {
    float3 nn = normalize(n);
    float kappa = k > 0.0 ? k : cdrf_screen_curvature(nn, p);
    float3 l = normalize(float3(0.3, 0.4, 0.8));
    return float4(cdrf_radiance(u_table, u_sampler, nn, l, float3(0.0, 0.0, 1.0), kappa,
                                float2(0.0, 200.0), 1.0, 1.4, 0.5, 0.2), 1.0);
}
"#;
    let args = ["-D", "-V", "-S", "frag", "-e", "main", "-o", "cdrf.spv"];
    compile(tool, "cdrf.hlsl", &format!("{HLSL}{main}"), &args);
    // A call with an argument missing is refused.
    let broken = HLSL.replacen("cdrf_fresnel(lh, eta)", "cdrf_fresnel(lh)", 1);
    let r =
        std::panic::catch_unwind(|| compile(tool, "cdrf.hlsl", &format!("{broken}{main}"), &args));
    assert!(r.is_err(), "a broken snippet compiled");
}

#[test]
fn wgsl_parses_and_validates_with_naga() {
    let main = r#"
@group(0) @binding(0) var u_table: texture_2d<f32>;
@group(0) @binding(1) var u_sampler: sampler;
@fragment
fn main(@location(0) normal: vec3<f32>, @location(1) position: vec3<f32>,
        @location(2) k: f32) -> @location(0) vec4<f32> {
    let n = normalize(normal);
    let s = cdrf_screen_curvature(n, position);
    let kappa = select(s, k, k > 0.0);
    let l = normalize(vec3<f32>(0.3, 0.4, 0.8));
    return vec4<f32>(cdrf_radiance(u_table, u_sampler, n, l, vec3<f32>(0.0, 0.0, 1.0), kappa,
                                   vec2<f32>(0.0, 200.0), 1.0, 1.4, 0.5, 0.2), 1.0);
}
"#;
    let validate = |src: &str| -> Result<(), String> {
        let module = naga::front::wgsl::parse_str(src).map_err(|e| e.emit_to_string(src))?;
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&module)
        .map(|_| ())
        .map_err(|e| format!("{e:?}"))
    };
    validate(&format!("{WGSL}{main}")).unwrap_or_else(|e| panic!("{e}"));
    // A type error (a vector where a scalar belongs) is refused.
    let broken = WGSL.replacen("return 1.0;", "return vec2<f32>(1.0);", 1);
    assert!(validate(&format!("{broken}{main}")).is_err());
}
