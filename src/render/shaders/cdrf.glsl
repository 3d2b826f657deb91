// workbench: shading with a measured CDRF table, as `workbench render` shades
// (src/render/raster.rs; conventions: the table's sidecar JSON and docs/engines.md).
// GLSL ES 3.00 (WebGL2) and desktop GLSL 3.30+; the same text is valid in Godot 4's shading
// language (include it from a .gdshaderinc).
//
//   L = table(u, v) * scale * T(n.v; eta) + ks * D * G1(n.l) * G1(n.v) * F(l.h; eta) / (4 n.v)
//
// n, l, v: unit vectors in one frame, l toward the light and v toward the eye (away from the
// surface). kappa: the surface's curvature in the preset's unit (1/m or 1/cm), from a vertex
// attribute (workbench's per-vertex curvature) or cdrf_screen_curvature. kappa_range, scale, eta,
// ks, alpha: the sidecar's curvature_range, value_scale, material.eta, material.specular.ks and
// material.specular.alpha. The result is radiance per unit of the photographed light: multiply
// by the light's colour (relative to the photographed light) and add it for each light.

const float CDRF_PI = 3.14159265358979;

// Exact unpolarised dielectric Fresnel reflectance from air into index eta.
float cdrf_fresnel(float cos_i, float eta) {
    float ci = clamp(cos_i, 0.0, 1.0);
    float si2 = 1.0 - ci * ci;
    float ct2 = 1.0 - si2 / (eta * eta);
    if (ct2 <= 0.0) {
        return 1.0;
    }
    float ct = sqrt(ct2);
    float rs = (ci - eta * ct) / (ci + eta * ct);
    float rp = (eta * ci - ct) / (eta * ci + ct);
    return 0.5 * (rs * rs + rp * rp);
}

// The GGX lobe times n.l, from n.l, n.v and l.v (0 unless n.l > 0 and n.v > 0).
float cdrf_specular(float nl, float nv, float lv, float ks, float alpha, float eta) {
    if (ks <= 0.0 || nl <= 0.0 || nv <= 0.0 || lv <= -1.0 + 1e-6) {
        return 0.0;
    }
    float nh = min((nl + nv) / sqrt(2.0 + 2.0 * lv), 1.0);
    float lh = sqrt(0.5 * (1.0 + lv));
    float a2 = alpha * alpha;
    float q = nh * nh * (a2 - 1.0) + 1.0;
    float d = a2 / (CDRF_PI * q * q);
    float gl = 2.0 * nl / (nl + sqrt(a2 + (1.0 - a2) * nl * nl));
    float gv = 2.0 * nv / (nv + sqrt(a2 + (1.0 - a2) * nv * nv));
    return ks * d * gl * gv * cdrf_fresnel(lh, eta) / (4.0 * nv);
}

// Radiance of one directional light.
vec3 cdrf_radiance(sampler2D table, vec3 n, vec3 l, vec3 v, float kappa, vec2 kappa_range,
                   float scale, float eta, float ks, float alpha) {
    float nv = dot(n, v);
    // An interpolated normal can face away near a silhouette: bend it just into view.
    if (nv < 1e-3) {
        n = normalize(n + (1e-3 - nv) * v);
        nv = max(dot(n, v), 1e-3);
    }
    float nl = dot(n, l);
    vec2 uv = vec2(nl * 0.5 + 0.5, (kappa - kappa_range.x) / (kappa_range.y - kappa_range.x));
    vec3 diffuse = textureLod(table, uv, 0.0).rgb * scale;
    float t = 1.0 - cdrf_fresnel(min(nv, 1.0), eta);
    return diffuse * t + vec3(cdrf_specular(nl, nv, dot(l, v), ks, alpha, eta));
}

// Screen-space curvature, an approximation for meshes without a curvature attribute:
// |fwidth(n)| / |fwidth(p)| (p the position in the unit of kappa's inverse; fragment stage only).
float cdrf_screen_curvature(vec3 n, vec3 p) {
    return length(fwidth(n)) / max(length(fwidth(p)), 1e-8);
}
