// WebGL2 Gaussian splat renderer (standard 3DGS EWA projection, format-spec/renderer.md):
// instanced quads, one per Gaussian, sorted back to front by view depth in wasm; the 2D
// covariance J W Σ Wᵀ Jᵀ + 0.3 I is computed in the vertex shader, the quad covers the ellipse
// where alpha can reach 1/255, and the fragment shader evaluates the Gaussian at the pixel's
// integer coordinates (the 3DGS ndc2Pix convention). Blending is premultiplied "over" into a
// half-float target (so dozens of layers do not round to 8 bits each), then copied to the canvas.
const TEX_W = 4096; // texels per row; 4 texels per Gaussian

const VS = `#version 300 es
precision highp float; precision highp int; precision highp sampler2D;
uniform sampler2D u_tex;
uniform mat3 u_w2c;      // t = u_w2c (p - c)
uniform vec3 u_cam;
uniform vec4 u_intr;     // fx fy cx cy
uniform vec2 u_size;     // W H
uniform vec2 u_lim;      // 1.3 tan(fov/2), x and y
out vec3 v_col; out float v_op; out vec3 v_conic; out vec2 v_mean;
vec4 fetch(int i) { return texelFetch(u_tex, ivec2(i % ${TEX_W}, i / ${TEX_W}), 0); }
void main() {
  int k = gl_InstanceID * 4;
  vec4 a = fetch(k), b = fetch(k + 1), c = fetch(k + 2), d = fetch(k + 3);
  vec3 t = u_w2c * (a.xyz - u_cam);
  gl_Position = vec4(0.0, 0.0, 2.0, 1.0); // culled unless set below
  if (!(t.z > 0.2) || !(a.w * 255.0 > 1.0)) return;
  mat3 S = mat3(b.x, b.y, b.z, b.y, b.w, c.x, b.z, c.x, c.y);
  float fx = u_intr.x, fy = u_intr.y;
  float tx = clamp(t.x / t.z, -u_lim.x, u_lim.x) * t.z;
  float ty = clamp(t.y / t.z, -u_lim.y, u_lim.y) * t.z;
  vec3 j0 = vec3(fx / t.z, 0.0, -fx * tx / (t.z * t.z));
  vec3 j1 = vec3(0.0, fy / t.z, -fy * ty / (t.z * t.z));
  mat3 wt = transpose(u_w2c);
  vec3 r0 = wt * j0, r1 = wt * j1;
  float A = dot(r0, S * r0) + 0.3, B = dot(r0, S * r1), C = dot(r1, S * r1) + 0.3;
  float det = A * C - B * B;
  if (!(det > 0.0)) return;
  v_conic = vec3(C / det, -B / det, A / det);
  v_mean = vec2(fx * t.x / t.z + u_intr.z - 0.5, fy * t.y / t.z + u_intr.w - 0.5);
  v_op = a.w; v_col = d.rgb;
  float r2 = 2.0 * log(255.0 * a.w);           // d^T conic d <= r2 holds alpha >= 1/255
  vec2 ext = sqrt(r2 * vec2(A, C)) + 1.0;
  vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)) * 2.0 - 1.0;
  vec2 px = v_mean + corner * ext;
  gl_Position = vec4((px.x + 0.5) / u_size.x * 2.0 - 1.0, 1.0 - (px.y + 0.5) / u_size.y * 2.0, 0.0, 1.0);
}`;

const FS = `#version 300 es
precision highp float;
uniform float u_h;
in vec3 v_col; in float v_op; in vec3 v_conic; in vec2 v_mean;
out vec4 o;
void main() {
  vec2 d = vec2(gl_FragCoord.x - 0.5, u_h - gl_FragCoord.y - 0.5) - v_mean;
  float power = -0.5 * (v_conic.x * d.x * d.x + v_conic.z * d.y * d.y) - v_conic.y * d.x * d.y;
  float al = min(0.99, v_op * exp(min(power, 0.0)));
  if (al < 1.0 / 255.0) discard;
  o = vec4(v_col * al, al);
}`;

const COPY_VS = `#version 300 es
void main() { vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2)); gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0); }`;
const COPY_FS = `#version 300 es
precision highp float; uniform sampler2D u_src; out vec4 o;
void main() { vec4 c = texelFetch(u_src, ivec2(gl_FragCoord.xy), 0); o = vec4(clamp(c.rgb, 0.0, 1.0), 1.0); }`;

function program(gl, vs, fs) {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error("link: " + gl.getProgramInfoLog(p));
  return p;
}

export class SplatRenderer {
  constructor(canvas) {
    this.canvas = canvas;
    const gl = canvas.getContext("webgl2", { antialias: false, premultipliedAlpha: false, preserveDrawingBuffer: true, alpha: false });
    if (!gl) throw new Error("WebGL2 is not available");
    this.gl = gl;
    this.float = !!gl.getExtension("EXT_color_buffer_float");
    this.prog = program(gl, VS, FS);
    this.copy = program(gl, COPY_VS, COPY_FS);
    this.tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, this.tex);
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
    this.vao = gl.createVertexArray();
    this.staging = new Float32Array(0);
    this.u = {};
    for (const n of ["u_tex", "u_w2c", "u_cam", "u_intr", "u_size", "u_lim", "u_h"]) this.u[n] = gl.getUniformLocation(this.prog, n);
    this.background = [1, 1, 1];
  }

  _target(w, h) {
    const gl = this.gl;
    if (!this.float) return null;
    if (this.fbo && this.fw === w && this.fh === h) return this.fbo;
    this.fbo = this.fbo || gl.createFramebuffer();
    this.ftex = this.ftex || gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, this.ftex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA16F, w, h, 0, gl.RGBA, gl.HALF_FLOAT, null);
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.fbo);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, this.ftex, 0);
    if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) { this.float = false; return null; }
    this.fw = w; this.fh = h;
    return this.fbo;
  }

  // splats: Float32Array of 16 floats per Gaussian (dlgs-web prepare_draw), back to front.
  // cam: { w2c: 9 floats row-major, pos: [x,y,z], fx, fy, cx, cy, width, height }.
  draw(splats, count, cam) {
    const gl = this.gl;
    const { width: W, height: H } = cam;
    if (this.canvas.width !== W || this.canvas.height !== H) { this.canvas.width = W; this.canvas.height = H; }
    const rows = Math.max(1, Math.ceil((count * 4) / TEX_W));
    const need = rows * TEX_W * 4;
    if (this.staging.length < need) this.staging = new Float32Array(need);
    this.staging.set(splats.subarray(0, count * 16));
    gl.bindTexture(gl.TEXTURE_2D, this.tex);
    if (this.texRows !== rows) {
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, TEX_W, rows, 0, gl.RGBA, gl.FLOAT, this.staging, 0);
      this.texRows = rows;
    } else {
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, TEX_W, rows, gl.RGBA, gl.FLOAT, this.staging, 0);
    }
    const fbo = this._target(W, H);
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
    gl.viewport(0, 0, W, H);
    const bg = this.background;
    gl.clearColor(bg[0], bg[1], bg[2], 1);
    gl.clear(gl.COLOR_BUFFER_BIT);
    gl.useProgram(this.prog);
    gl.enable(gl.BLEND);
    gl.blendFuncSeparate(gl.ONE, gl.ONE_MINUS_SRC_ALPHA, gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
    gl.disable(gl.DEPTH_TEST);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.tex);
    gl.uniform1i(this.u.u_tex, 0);
    gl.uniformMatrix3fv(this.u.u_w2c, true, cam.w2c);
    gl.uniform3fv(this.u.u_cam, cam.pos);
    gl.uniform4f(this.u.u_intr, cam.fx, cam.fy, cam.cx, cam.cy);
    gl.uniform2f(this.u.u_size, W, H);
    gl.uniform2f(this.u.u_lim, 1.3 * (W / (2 * cam.fx)), 1.3 * (H / (2 * cam.fy)));
    gl.uniform1f(this.u.u_h, H);
    gl.bindVertexArray(this.vao);
    if (count > 0) gl.drawArraysInstanced(gl.TRIANGLE_STRIP, 0, 4, count);
    gl.disable(gl.BLEND);
    if (fbo) {
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.useProgram(this.copy);
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, this.ftex);
      gl.uniform1i(gl.getUniformLocation(this.copy, "u_src"), 0);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    }
  }

  // RGBA8 pixels of the canvas, top row first.
  pixels() {
    const gl = this.gl, W = this.canvas.width, H = this.canvas.height;
    const p = new Uint8Array(W * H * 4);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.readPixels(0, 0, W, H, gl.RGBA, gl.UNSIGNED_BYTE, p);
    const out = new Uint8Array(W * H * 4);
    for (let y = 0; y < H; y++) out.set(p.subarray((H - 1 - y) * W * 4, (H - y) * W * 4), y * W * 4);
    return out;
  }
}
