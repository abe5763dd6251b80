//! Gaussians no renderer draws. 3DGS compositing skips a Gaussian at a pixel where its alpha
//! `o · exp(power)` is below 1/255, and `exp(power) <= 1`; so a Gaussian whose colour opacity
//! (and language opacity, when the scene has language) is below 1/255 adds nothing to any
//! image, from any camera, at any resolution. Anti-aliased variants (Mip-Splatting, gsplat's
//! `antialiased`) only lower the opacity. Dropping such Gaussians from a still scene changes no
//! pixel and saves their bytes (3.3 % of the Mip-Splatting donut).

use dlgs::model::sigmoid;
use dlgs::Gaussians;

/// True when Gaussian `i` cannot reach alpha 1/255 anywhere, in colour or language.
pub fn never_drawn(g: &Gaussians, i: usize) -> bool {
    let below = |logit: f32| sigmoid(logit) * 255.0 < 1.0;
    below(g.opacity[i]) && (!g.has_language() || below(g.lang_opacity[i]))
}

/// `g` without its never-drawn Gaussians, in the same order, and how many were dropped.
/// NaN opacities are kept (the encoder's finiteness check reports them).
pub fn drop_never_drawn(g: &Gaussians) -> (Gaussians, usize) {
    let mut out = Gaussians::new(g.sh_degree, g.lang_width);
    for i in 0..g.len() {
        if !never_drawn(g, i) {
            out.push_from(g, i);
        }
    }
    let dropped = g.len() - out.len();
    (out, dropped)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(opacities: &[f32], lang: Option<&[f32]>) -> Gaussians {
        let mut g = Gaussians::new(0, if lang.is_some() { 1 } else { 0 });
        for (i, &o) in opacities.iter().enumerate() {
            g.positions.push([i as f32 * 0.1, 0.0, 0.0]);
            g.log_scales.push([-2.0; 3]);
            g.rotations.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity.push(o);
            g.sh.extend_from_slice(&[0.1, 0.2, 0.3]);
            if let Some(l) = lang {
                g.lang_opacity.push(l[i]);
                g.lang.push(i as f32);
            }
        }
        g
    }

    #[test]
    fn drops_only_what_stays_under_one_255th() {
        // logit(1/255) = -5.5413; just above it is kept.
        let g = scene(
            &[-5.6, -5.53, 0.0, -30.0, f32::NEG_INFINITY, f32::NAN],
            None,
        );
        let (kept, dropped) = drop_never_drawn(&g);
        assert_eq!(dropped, 3);
        assert_eq!(kept.opacity.len(), 3);
        assert_eq!(kept.opacity[..2], [-5.53, 0.0]);
        assert!(kept.opacity[2].is_nan());
        assert_eq!(kept.positions[1], g.positions[2]);
    }

    #[test]
    fn language_opacity_keeps_a_gaussian() {
        let g = scene(&[-9.0, -9.0], Some(&[2.0, -9.0]));
        let (kept, dropped) = drop_never_drawn(&g);
        assert_eq!(dropped, 1);
        assert_eq!(kept.lang, vec![0.0]);
    }
}
