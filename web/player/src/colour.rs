//! A splat's colour: the SH at the view direction (the CPU renderer's), or the relevance heat map.

pub(crate) fn heat(u: f32) -> [f32; 3] {
    // Blue -> cyan -> green -> yellow -> red.
    let u = u.clamp(0.0, 1.0) * 4.0;
    let (r, g, b) = match u as u32 {
        0 => (0.0, u, 1.0),
        1 => (0.0, 1.0, 2.0 - u),
        2 => (u - 2.0, 1.0, 0.0),
        _ => (1.0, (4.0 - u).max(0.0), 0.0),
    };
    [r, g, b]
}

/// The SH colour at the view direction: the CPU renderer's own sum (`render/src/sh.rs`), so the
/// page and `dlgs render` colour a splat alike.
pub(crate) use dlgs_render::sh::eval_sh;
