// Cameras for the web player (page and decoder worker): 3DGS cameras.json entries and orbits.

// A 3DGS cameras.json entry -> renderer camera (rotation is camera-to-world, rows).
export function cameraFromJson(c, width, height) {
  const r = c.rotation; const W = width || c.width, H = height || c.height;
  const sx = W / c.width, sy = H / c.height;
  return {
    w2c: [r[0][0], r[1][0], r[2][0], r[0][1], r[1][1], r[2][1], r[0][2], r[1][2], r[2][2]],
    pos: c.position.slice(), fx: c.fx * sx, fy: c.fy * sy, cx: W / 2, cy: H / 2, width: W, height: H,
  };
}

// An orbit camera: yaw/pitch around a centre, up -y (COLMAP scenes), as `dlgs render --orbit`.
export function orbitCamera(center, dist, yaw, pitch, width, height, fovDeg = 50) {
  const cp = Math.cos(pitch), sp = Math.sin(pitch);
  const pos = [center[0] + dist * cp * Math.sin(yaw), center[1] - dist * sp, center[2] - dist * cp * Math.cos(yaw)];
  const f = [center[0] - pos[0], center[1] - pos[1], center[2] - pos[2]];
  const fl = Math.hypot(...f); const z = f.map((v) => v / fl);
  const up = [0, -1, 0];
  let x = [z[1] * up[2] - z[2] * up[1], z[2] * up[0] - z[0] * up[2], z[0] * up[1] - z[1] * up[0]];
  const xl = Math.hypot(...x) || 1; x = x.map((v) => v / xl);
  const y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]];
  const fx = width / (2 * Math.tan((fovDeg * Math.PI) / 360));
  return { w2c: [...x, ...y, ...z], pos, fx, fy: fx, cx: width / 2, cy: height / 2, width, height };
}

