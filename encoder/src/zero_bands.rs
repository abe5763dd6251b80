//! SH bands that are zero in every Gaussian. Some trained scenes are written with SH degree 3
//! but never learned view dependence (the gs3d lod tiles: all 45 band 1-3 coefficients are 0.0
//! in every Gaussian). A zero band adds nothing to any colour, so a lossy still scene stored at
//! the highest degree that holds a non-zero coefficient renders the same pixels, and its file
//! saves the band channels' records (14 bytes each, 630 bytes for bands 1-3 per part: 2.3 % of the
//! 1,971-Gaussian lod tile at `high`).

use dlgs::model::sh_coeffs;
use dlgs::Gaussians;

/// The lowest SH degree that keeps every non-zero coefficient of `g` (`g.sh_degree` when the
/// top band holds one). NaN counts as non-zero: the encoder's finiteness check reports it.
pub fn degree_in_use(g: &Gaussians) -> u8 {
    let stride = g.sh_stride();
    let mut used = 0u8;
    for degree in (1..=g.sh_degree).rev() {
        let band = sh_coeffs(degree - 1) * 3..sh_coeffs(degree) * 3;
        let non_zero =
            g.sh.chunks_exact(stride)
                .any(|s| s[band.clone()].iter().any(|&c| c != 0.0));
        if non_zero {
            used = degree;
            break;
        }
    }
    used
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(degree: u8, sh: impl Fn(usize, usize) -> f32) -> Gaussians {
        let mut g = Gaussians::new(degree, 0);
        for i in 0..4 {
            g.positions.push([i as f32, 0.0, 0.0]);
            g.log_scales.push([-2.0; 3]);
            g.rotations.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity.push(0.0);
            g.sh.extend((0..g.sh_stride()).map(|j| sh(i, j)));
        }
        g
    }

    #[test]
    fn the_degree_in_use_is_the_highest_band_with_a_non_zero_coefficient() {
        // DC only: degree 0, whatever the declared degree.
        assert_eq!(
            degree_in_use(&scene(3, |_, j| if j < 3 { 0.5 } else { 0.0 })),
            0
        );
        // One coefficient of band 2 (coefficients 4..9, floats 12..27) in one Gaussian.
        let g = scene(3, |i, j| if i == 2 && j == 14 { -1e-30 } else { 0.0 });
        assert_eq!(degree_in_use(&g), 2);
        // The last float of band 3, and -0.0 elsewhere (zero).
        let g = scene(3, |i, j| match (i, j) {
            (3, 47) => 0.25,
            _ => -0.0,
        });
        assert_eq!(degree_in_use(&g), 3);
        // NaN is not zero.
        assert_eq!(
            degree_in_use(&scene(1, |_, j| if j == 5 { f32::NAN } else { 0.0 })),
            1
        );
        assert_eq!(degree_in_use(&scene(0, |_, _| 0.0)), 0);
        assert_eq!(degree_in_use(&Gaussians::new(3, 0)), 0);
    }
}
