// workbench's viewer: the measured material on a sphere row and a mesh, in WebGL2, shaded by the
// same GLSL snippet `workbench lut --preset generic` writes (cdrf.glsl), with the camera, light
// and exposure of `workbench render`. No network: everything comes from data.js beside this file.
"use strict";

function fail(msg) {
  const e = document.getElementById("error");
  e.textContent = "workbench viewer: " + msg;
  e.style.display = "block";
  document.getElementById("stage").style.display = "none";
  document.title = "workbench viewer: error";
  throw new Error(msg);
}

function bytes(b64) {
  const s = atob(b64);
  const out = new Uint8Array(s.length);
  for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
  return out.buffer;
}

// The fit as the viewer needs it: every field checked, one message naming what is wrong.
function checkFit(fit) {
  if (!fit || typeof fit !== "object") fail("fit.json: not an object");
  if (typeof fit.schema !== "string" || !fit.schema.startsWith("workbench.fit/"))
    fail("fit.json: schema is not workbench.fit/…");
  const num = (x) => typeof x === "number" && isFinite(x);
  if (!num(fit.eta) || fit.eta < 1) fail("fit.json: eta must be a number ≥ 1");
  for (const k of ["sigma0_mm", "albedo"])
    if (!Array.isArray(fit[k]) || fit[k].length !== 3 || !fit[k].every(num))
      fail("fit.json: " + k + " must be three numbers");
  const s = fit.specular || { ks: 0, alpha: 0.1 };
  if (!num(s.ks) || !num(s.alpha) || s.alpha <= 0) fail("fit.json: specular ks and alpha must be numbers, alpha > 0");
  return { eta: fit.eta, ks: s.ks, alpha: s.alpha };
}

function compile(gl, type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) fail("shader: " + gl.getShaderInfoLog(s));
  return s;
}

const VERTEX = `#version 300 es
precision highp float;
in vec3 a_position; in vec3 a_normal; in float a_kappa;
uniform mat3 u_rot; uniform vec3 u_eye; uniform vec4 u_k; uniform vec2 u_size; uniform vec2 u_depth;
// centroid: a pixel the surface only partly covers is shaded inside the surface, as workbench
// render shades it at the centroid of its covered samples (not at the pixel centre beyond it).
centroid out vec3 v_normal; centroid out vec3 v_position; centroid out float v_kappa;
void main() {
  // Camera frame as workbench render's (OpenCV: x right, y down, z forward), then the pinhole
  // fx, fy, cx, cy with pixel i's centre at x = i, and GL's window y up.
  vec3 p = u_rot * (a_position - u_eye);
  v_position = p; v_normal = u_rot * a_normal; v_kappa = a_kappa;
  float xw = u_k.x * p.x + (u_k.z + 0.5) * p.z;
  float yw = u_k.y * p.y + (u_k.w + 0.5) * p.z;
  // Depth from near to far (u_depth) as in any perspective projection.
  float a = (u_depth.y + u_depth.x) / (u_depth.y - u_depth.x);
  float b = -2.0 * u_depth.y * u_depth.x / (u_depth.y - u_depth.x);
  gl_Position = vec4(2.0 * xw / u_size.x - p.z, p.z - 2.0 * yw / u_size.y, a * p.z + b, p.z);
}`;

const FRAGMENT_MAIN = `
uniform sampler2D u_table; uniform vec3 u_light; uniform vec2 u_kappa_range;
uniform float u_scale; uniform float u_eta; uniform float u_ks; uniform float u_alpha;
uniform float u_exposure; uniform bool u_tone;
centroid in vec3 v_normal; centroid in vec3 v_position; centroid in float v_kappa;
out vec4 color;
float srgb(float x) { return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055; }
vec4 tone(vec3 L) {
  vec3 y = clamp(L * u_exposure, 0.0, 1.0);
  return vec4(srgb(y.r), srgb(y.g), srgb(y.b), 1.0);
}
void main() {
  vec3 n = normalize(v_normal);
  vec3 v = -normalize(v_position);
  vec3 L = cdrf_radiance(u_table, n, u_light, v, v_kappa, u_kappa_range, u_scale, u_eta, u_ks, u_alpha);
  // Linear radiance into the multisampled float buffer (tone-mapped after the resolve, as
  // workbench render averages a pixel's samples before its transfer curve), or straight to the
  // canvas where float buffers are missing.
  color = u_tone ? tone(L) : vec4(L, 1.0);
}`;

// The resolved linear picture, exposed and sRGB-encoded, pixel for pixel.
const TONE_VERTEX = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}`;
const TONE_FRAGMENT = `#version 300 es
precision highp float;
uniform sampler2D u_image; uniform float u_exposure;
out vec4 color;
float srgb(float x) { return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055; }
void main() {
  vec3 y = clamp(texelFetch(u_image, ivec2(gl_FragCoord.xy), 0).rgb * u_exposure, 0.0, 1.0);
  color = vec4(srgb(y.r), srgb(y.g), srgb(y.b), 1.0);
}`;

function main() {
  if (window.WORKBENCH_ERRORS.length) fail("data.js did not load: " + window.WORKBENCH_ERRORS.join("; "));
  const data = window.WORKBENCH;
  if (!data || !data.scene) fail("data.js is missing or has no scene (run workbench view again)");
  const material = checkFit(data.fit);
  const sc = data.scene;
  const shot = /(^|[#&])shot=(\d+)x(\d+)/.exec(location.hash);
  const canvas = document.getElementById("view");
  if (shot) {
    document.body.classList.add("shot");
    canvas.width = +shot[2]; canvas.height = +shot[3];
  }
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
  if (!gl) fail("this browser has no WebGL2");
  const float_targets = !!gl.getExtension("EXT_color_buffer_float");
  const prog = gl.createProgram();
  gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER,
    "#version 300 es\nprecision highp float;\n" + sc.glsl + FRAGMENT_MAIN));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) fail("shader link: " + gl.getProgramInfoLog(prog));
  gl.useProgram(prog);

  // The generic preset's table: top-left origin, so no flip; half floats, bilinear, clamped.
  const t = sc.table;
  const tex = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, tex);
  gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB16F, t.width, t.height, 0, gl.RGB, gl.HALF_FLOAT,
    new Uint16Array(bytes(t.half_rgb)));
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
    [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]])
    gl.texParameteri(gl.TEXTURE_2D, k, v);
  const u = (name) => gl.getUniformLocation(prog, name);
  gl.uniform1i(u("u_table"), 0);
  gl.uniform2f(u("u_kappa_range"), t.kappa_range[0], t.kappa_range[1]);
  gl.uniform1f(u("u_scale"), t.scale);
  gl.uniform1f(u("u_eta"), material.eta);
  gl.uniform1f(u("u_ks"), material.ks);
  gl.uniform1f(u("u_alpha"), material.alpha);
  gl.uniform1f(u("u_exposure"), sc.exposure);

  function upload(m) {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    for (const [name, b64, size] of [["a_position", m.positions, 3], ["a_normal", m.normals, 3], ["a_kappa", m.kappa, 1]]) {
      const buf = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, buf);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(bytes(b64)), gl.STATIC_DRAW);
      const loc = gl.getAttribLocation(prog, name);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
    }
    const ib = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
    const idx = new Uint32Array(bytes(m.indices));
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
    return { vao: vao, count: idx.length, centre: m.centre, radius: m.radius };
  }
  const meshes = { spheres: upload(sc.spheres), mesh: sc.mesh ? upload(sc.mesh) : null };
  if (!meshes.mesh) document.getElementById("mesh-radio").disabled = true;

  const state = {
    scene: /(^|[#&])mesh($|&)/.test(location.hash) && meshes.mesh ? "mesh" : "spheres",
    az: sc.view.azimuth_deg, el: sc.view.elevation_deg, dist: sc.view.distance,
    light_az: sc.light_deg[0], light_el: sc.light_deg[1],
  };
  for (const r of document.querySelectorAll("input[name=scene]")) {
    r.checked = r.value === state.scene;
    r.addEventListener("change", () => { state.scene = r.value; draw(); });
  }

  // Four samples a pixel into a linear float buffer, resolved (averaged) into a texture, then
  // exposed and encoded: workbench render's order. Without float render targets the canvas's
  // own multisampling averages the encoded values instead (edges then differ).
  let targets = null;
  function makeTargets(W, H) {
    if (!float_targets) return null;
    const samples = Math.min(4, gl.getParameter(gl.MAX_SAMPLES));
    const ms = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, ms);
    for (const [fmt, at] of [[gl.RGBA16F, gl.COLOR_ATTACHMENT0], [gl.DEPTH_COMPONENT24, gl.DEPTH_ATTACHMENT]]) {
      const rb = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, rb);
      gl.renderbufferStorageMultisample(gl.RENDERBUFFER, samples, fmt, W, H);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, at, gl.RENDERBUFFER, rb);
    }
    const image = gl.createTexture();
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, image);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA16F, W, H);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.activeTexture(gl.TEXTURE0);
    const resolved = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, resolved);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, image, 0);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    const tp = gl.createProgram();
    gl.attachShader(tp, compile(gl, gl.VERTEX_SHADER, TONE_VERTEX));
    gl.attachShader(tp, compile(gl, gl.FRAGMENT_SHADER, TONE_FRAGMENT));
    gl.linkProgram(tp);
    if (!gl.getProgramParameter(tp, gl.LINK_STATUS)) fail("shader link: " + gl.getProgramInfoLog(tp));
    return { ms: ms, resolved: resolved, prog: tp, W: W, H: H, samples: samples };
  }

  function draw() {
    const m = meshes[state.scene];
    const W = canvas.width, H = canvas.height;
    if (float_targets && (!targets || targets.W !== W || targets.H !== H)) targets = makeTargets(W, H);
    gl.useProgram(prog);
    gl.uniform1i(u("u_tone"), targets ? 0 : 1);
    gl.bindFramebuffer(gl.FRAMEBUFFER, targets ? targets.ms : null);
    gl.viewport(0, 0, W, H);
    gl.clearColor(0, 0, 0, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    // workbench render's camera: horizontal field of view fov, f = W/2 / tan(fov/2), the
    // principal point at the centre; the mesh's bounding sphere framed at `distance`.
    const f = 0.5 * W / Math.tan(0.5 * sc.fov_deg * Math.PI / 180);
    const half = Math.min(Math.atan(0.5 * W / f), Math.atan(0.5 * H / f));
    const az = state.az * Math.PI / 180, el = Math.max(-89, Math.min(89, state.el)) * Math.PI / 180;
    const dir = [Math.sin(az) * Math.cos(el), Math.sin(el), Math.cos(az) * Math.cos(el)];
    const d = state.dist * Math.max(m.radius, 1e-9) / Math.sin(half);
    const eye = [0, 1, 2].map((i) => m.centre[i] + dir[i] * d);
    const z = dir.map((x) => -x);
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]); return a.map((x) => x / l); };
    const x = norm(cross(z, [0, 1, 0]));
    const y = cross(z, x);
    // R has rows x, y, z; WebGL takes a mat3 column by column.
    gl.uniformMatrix3fv(u("u_rot"), false, [x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2]]);
    gl.uniform3fv(u("u_eye"), eye);
    gl.uniform4f(u("u_k"), f, f, 0.5 * (W - 1), 0.5 * (H - 1));
    gl.uniform2f(u("u_size"), W, H);
    gl.uniform2f(u("u_depth"), Math.max(d - 2 * m.radius, 1e-3 * d), d + 2 * m.radius);
    const la = state.light_az * Math.PI / 180, le = state.light_el * Math.PI / 180;
    gl.uniform3f(u("u_light"), Math.cos(le) * Math.sin(la), -Math.sin(le), -Math.cos(le) * Math.cos(la));
    gl.bindVertexArray(m.vao);
    gl.drawElements(gl.TRIANGLES, m.count, gl.UNSIGNED_INT, 0);
    if (targets) {
      gl.bindFramebuffer(gl.READ_FRAMEBUFFER, targets.ms);
      gl.bindFramebuffer(gl.DRAW_FRAMEBUFFER, targets.resolved);
      gl.blitFramebuffer(0, 0, W, H, 0, 0, W, H, gl.COLOR_BUFFER_BIT, gl.NEAREST);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.disable(gl.DEPTH_TEST);
      gl.useProgram(targets.prog);
      gl.activeTexture(gl.TEXTURE1);
      gl.uniform1i(gl.getUniformLocation(targets.prog, "u_image"), 1);
      gl.uniform1f(gl.getUniformLocation(targets.prog, "u_exposure"), sc.exposure);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
      gl.activeTexture(gl.TEXTURE0);
    }
    document.getElementById("info").textContent =
      `camera azimuth ${state.az.toFixed(1)}°, elevation ${state.el.toFixed(1)}°, distance ${state.dist.toFixed(2)} · ` +
      `light azimuth ${state.light_az.toFixed(1)}°, elevation ${state.light_el.toFixed(1)}° (camera frame) · ` +
      `η ${material.eta.toFixed(3)}, ks ${material.ks.toPrecision(3)}, α ${material.alpha.toFixed(3)}` +
      (targets ? ` · ${targets.samples} samples a pixel, averaged linearly` : " · no float render targets: edges averaged after the sRGB curve");
    document.title = "workbench viewer";
  }

  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, light: e.shiftKey || e.button === 2 }; });
  window.addEventListener("pointerup", () => { drag = null; });
  window.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.light) {
      state.light_az += 0.4 * dx;
      state.light_el = Math.max(-89, Math.min(89, state.light_el - 0.4 * dy));
    } else {
      state.az -= 0.4 * dx;
      state.el = Math.max(-89, Math.min(89, state.el + 0.4 * dy));
    }
    draw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    state.dist = Math.max(1, state.dist * Math.exp(0.001 * e.deltaY));
    draw();
  }, { passive: false });

  const figs = document.getElementById("figures");
  for (const f of sc.figures) {
    const a = document.createElement("a");
    a.href = f; a.textContent = f.split("/").pop();
    figs.appendChild(a);
  }
  document.getElementById("title").textContent = "workbench: " + (data.fit.session || "fit");
  draw();
}

main();
