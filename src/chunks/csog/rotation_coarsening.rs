//! Coarse rotations (layout 3, §6.5.6): rotations of small Gaussians stored a few bits
//! coarser, and the order their cells are stored in.

use super::channels::FIRST_ROTATION;
use super::quantiser::{levels, position_steps};

/// Largest rotation shift a layout-3 set may give (§6.5.6).
pub const MAX_ROTATION_SHIFT: u8 = 8;

/// How many bits coarser a Gaussian's three stored rotation components are (§6.5.6): the
/// number of halvings from `exp(threshold)` down to its largest scale, at most `max_shift`.
/// A rotation error turns a Gaussian by an angle that moves its surface by about the angle
/// times its largest scale: a small Gaussian may turn more for the same displacement.
/// f32 arithmetic in this order, so every reader gets the same shifts from the same file.
pub fn rotation_shift(log_scale: [f32; 3], threshold: f32, max_shift: u8) -> u8 {
    let largest = log_scale[0].max(log_scale[1]).max(log_scale[2]);
    let x = (threshold - largest) * std::f32::consts::LOG2_E;
    if x >= 1.0 {
        x.floor().min(max_shift as f32) as u8
    } else {
        0
    }
}

/// Encoder setting for layout 3 (§6.5.6): rotations of Gaussians smaller than `factor`
/// position steps per rotation step are stored up to `max_shift` bits coarser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationCoarsening {
    /// Surface displacement allowed by one (coarsened) rotation step, in position steps.
    pub factor: f32,
    pub max_shift: u8,
}

impl RotationCoarsening {
    /// The reference encoder's default (`dlgs encode` without `--coarse-rotations`): on the
    /// real SH 0 scenes and gsplat 1-4 % fewer bytes for 0.00-0.33 dB
    /// (docs/benchmarks/canonical-levers.md "Coarse rotations").
    pub const DEFAULT: RotationCoarsening = RotationCoarsening {
        factor: 1.0,
        max_shift: 4,
    };
}

/// The stored (max shift, threshold) of a set whose channels hold `chans` (positions
/// quantised): `exp(threshold)` is the largest scale whose one-step turn moves its surface by
/// `factor` position steps. Shift 0 (no coarsening) when that is not finite.
#[allow(clippy::disallowed_methods)] // encoder-side: the threshold is stored
pub(super) fn coarsening_record(
    chans: &[(u8, f32, f32, Vec<u16>)],
    c: RotationCoarsening,
) -> (u8, f32) {
    let step = position_steps(chans).into_iter().fold(0.0f64, f64::max);
    let rot_bits = chans[FIRST_ROTATION].0;
    // One rotation step turns by about twice the component step, 2 * sqrt(2) / levels.
    let turn = 2.0 * std::f64::consts::SQRT_2 / levels(rot_bits) as f64;
    let t = (c.factor as f64 * step / turn).ln() as f32;
    if t.is_finite() && c.max_shift > 0 {
        (c.max_shift.min(MAX_ROTATION_SHIFT), t)
    } else {
        (0, 0.0)
    }
}

/// Layout 3 stores the rotation index and components of the cells with shift 0 first, then
/// those with shift 1, and so on, each class in grid order (§6.5.6): the coders' adaptive
/// models then learn one class's narrower values at a time. `order[j]` = grid cell stored
/// `j`-th.
pub fn cells_by_shift(shifts: &[u8]) -> Vec<u32> {
    // A counting sort: stable and linear (at most 256 classes).
    let mut start = [0usize; 257];
    for &s in shifts {
        start[s as usize + 1] += 1;
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    let mut order = vec![0u32; shifts.len()];
    for (i, &s) in shifts.iter().enumerate() {
        order[start[s as usize]] = i as u32;
        start[s as usize] += 1;
    }
    order
}

/// `2^-shift` (exact in f32).
pub(super) fn halvings(shift: u8) -> f32 {
    1.0 / (1u32 << shift) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_shifts_count_halvings_and_survive_degenerate_scales() {
        let t = 0.0f32; // exp(threshold) = 1
        let ln2 = std::f32::consts::LN_2;
        // Largest scale 1: no shift; 1/2 (one halving): 1; 1/4: 2; far below: the max.
        assert_eq!(rotation_shift([0.0, -5.0, -9.0], t, 4), 0);
        assert_eq!(rotation_shift([-ln2 * 1.0001, -9.0, -9.0], t, 4), 1);
        assert_eq!(rotation_shift([-9.0, -ln2 * 2.0001, -9.0], t, 4), 2);
        assert_eq!(rotation_shift([-30.0; 3], t, 4), 4);
        assert_eq!(rotation_shift([-30.0; 3], t, 0), 0, "max shift 0 = off");
        // Larger than exp(threshold), NaN or infinite: defined, never a panic.
        assert_eq!(rotation_shift([3.0; 3], t, 4), 0);
        assert_eq!(rotation_shift([f32::NAN; 3], t, 4), 0);
        assert_eq!(rotation_shift([f32::NAN, -30.0, f32::NAN], t, 4), 4);
        assert_eq!(rotation_shift([f32::INFINITY; 3], t, 4), 0);
        assert_eq!(rotation_shift([f32::NEG_INFINITY; 3], t, 8), 8);
    }

    #[test]
    fn cells_by_shift_is_a_stable_grouping() {
        assert_eq!(cells_by_shift(&[2, 0, 1, 0, 2]), vec![1, 3, 2, 0, 4]);
        assert!(cells_by_shift(&[]).is_empty());
    }
}
