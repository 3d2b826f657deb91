// workbench: shading with a measured CDRF table, as `workbench render` shades
// (src/render/raster.rs; conventions: the table's sidecar JSON and docs/engines.md). WGSL
// (WebGPU, wgpu).
//
//   L = table(u, v) * scale * T(n.v; eta) + ks * D * G1(n.l) * G1(n.v) * F(l.h; eta) / (4 n.v)
//
// n, l, v: unit vectors in one frame, l toward the light and v toward the eye (away from the
// surface). kappa: the surface's curvature in the preset's unit (1/m or 1/cm), from a vertex
// attribute (workbench's per-vertex curvature) or cdrf_screen_curvature. kappa_range, scale, eta,
// ks, alpha: the sidecar's curvature_range, value_scale, material.eta, material.specular.ks and
// material.specular.alpha. The result is radiance per unit of the photographed light: multiply
// by the light's colour (relative to it) and add it for each light. WebGPU's texture origin is
// the top-left: use the generic preset's table.

const CDRF_PI: f32 = 3.14159265358979;

// Exact unpolarised dielectric Fresnel reflectance from air into index eta.
fn cdrf_fresnel(cos_i: f32, eta: f32) -> f32 {
    let ci = clamp(cos_i, 0.0, 1.0);
    let si2 = 1.0 - ci * ci;
    let ct2 = 1.0 - si2 / (eta * eta);
    if (ct2 <= 0.0) {
        return 1.0;
    }
    let ct = sqrt(ct2);
    let rs = (ci - eta * ct) / (ci + eta * ct);
    let rp = (eta * ci - ct) / (eta * ci + ct);
    return 0.5 * (rs * rs + rp * rp);
}

// The GGX lobe times n.l, from n.l, n.v and l.v (0 unless n.l > 0 and n.v > 0).
fn cdrf_specular(nl: f32, nv: f32, lv: f32, ks: f32, alpha: f32, eta: f32) -> f32 {
    if (ks <= 0.0 || nl <= 0.0 || nv <= 0.0 || lv <= -1.0 + 1e-6) {
        return 0.0;
    }
    let nh = min((nl + nv) / sqrt(2.0 + 2.0 * lv), 1.0);
    let lh = sqrt(0.5 * (1.0 + lv));
    let a2 = alpha * alpha;
    let q = nh * nh * (a2 - 1.0) + 1.0;
    let d = a2 / (CDRF_PI * q * q);
    let gl = 2.0 * nl / (nl + sqrt(a2 + (1.0 - a2) * nl * nl));
    let gv = 2.0 * nv / (nv + sqrt(a2 + (1.0 - a2) * nv * nv));
    return ks * d * gl * gv * cdrf_fresnel(lh, eta) / (4.0 * nv);
}

// Radiance of one directional light.
fn cdrf_radiance(table: texture_2d<f32>, table_sampler: sampler, n_in: vec3<f32>, l: vec3<f32>,
                 v: vec3<f32>, kappa: f32, kappa_range: vec2<f32>, scale: f32, eta: f32,
                 ks: f32, alpha: f32) -> vec3<f32> {
    var n = n_in;
    var nv = dot(n, v);
    // An interpolated normal can face away near a silhouette: bend it just into view.
    if (nv < 1e-3) {
        n = normalize(n + (1e-3 - nv) * v);
        nv = max(dot(n, v), 1e-3);
    }
    let nl = dot(n, l);
    let uv = vec2<f32>(nl * 0.5 + 0.5, (kappa - kappa_range.x) / (kappa_range.y - kappa_range.x));
    let diffuse = textureSampleLevel(table, table_sampler, uv, 0.0).rgb * scale;
    let t = 1.0 - cdrf_fresnel(min(nv, 1.0), eta);
    return diffuse * t + vec3<f32>(cdrf_specular(nl, nv, dot(l, v), ks, alpha, eta));
}

// Screen-space curvature, an approximation for meshes without a curvature attribute:
// |fwidth(n)| / |fwidth(p)| (p the position in the unit of kappa's inverse; fragment stage only).
fn cdrf_screen_curvature(n: vec3<f32>, p: vec3<f32>) -> f32 {
    return length(fwidth(n)) / max(length(fwidth(p)), 1e-8);
}
