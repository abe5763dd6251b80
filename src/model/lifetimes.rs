//! Which dynamic Gaussians a GOP shows at which of its frames (format-spec §6.14, `LIFE`):
//! per-frame sequences gain and lose Gaussians, so a dynamic Gaussian may be shown for only
//! part of a GOP. Gaussians without an entry are shown at every frame.

/// Pre-sigmoid opacity a hidden Gaussian is given (colour and language): its sigmoid is 0 in
/// binary32, so no renderer draws it (§6.14).
pub const HIDDEN_OPACITY: f32 = -1.0e4;

/// One dynamic Gaussian's frames: shown at local frame `f` iff `first <= f <= last`
/// (`first > last`: never shown in this GOP).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Life {
    pub index: u32,
    pub first: u16,
    pub last: u16,
}

impl Life {
    pub fn shows(&self, local_frame: u32) -> bool {
        u32::from(self.first) <= local_frame && local_frame <= u32::from(self.last)
    }
}

/// The entries of one GOP, in strictly increasing `index` order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Lifetimes {
    pub entries: Vec<Life>,
}

impl Lifetimes {
    /// From per-Gaussian `(first, last)` frames over `n` dynamic Gaussians of a GOP of
    /// `frames` frames: entries only for those not shown at every frame.
    pub fn from_ranges(ranges: &[(u16, u16)], frames: u16) -> Option<Lifetimes> {
        let entries: Vec<Life> = ranges
            .iter()
            .enumerate()
            .filter(|(_, &(a, b))| !(a == 0 && b >= frames.saturating_sub(1)))
            .map(|(i, &(first, last))| Life {
                index: i as u32,
                first,
                last,
            })
            .collect();
        (!entries.is_empty()).then_some(Lifetimes { entries })
    }

    /// Hide the Gaussians not shown at GOP-local frame `local_frame`: their opacities become
    /// [`HIDDEN_OPACITY`]. `lang_opacity` is empty or one value per Gaussian.
    pub fn hide(&self, local_frame: u32, opacity: &mut [f32], lang_opacity: &mut [f32]) {
        for e in &self.entries {
            if e.shows(local_frame) {
                continue;
            }
            let i = e.index as usize;
            if let Some(o) = opacity.get_mut(i) {
                *o = HIDDEN_OPACITY;
            }
            if let Some(o) = lang_opacity.get_mut(i) {
                *o = HIDDEN_OPACITY;
            }
        }
    }

    /// How many Gaussians are shown at `local_frame` out of `n`.
    pub fn shown(&self, local_frame: u32, n: usize) -> usize {
        n - self
            .entries
            .iter()
            .filter(|e| !e.shows(local_frame))
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_only_for_partial_lives_and_hiding_follows_them() {
        let l = Lifetimes::from_ranges(&[(0, 9), (3, 9), (0, 4), (u16::MAX, 0)], 10).unwrap();
        assert_eq!(
            l.entries.iter().map(|e| e.index).collect::<Vec<_>>(),
            vec![1, 2, 3]
        );
        assert!(Lifetimes::from_ranges(&[(0, 9), (0, 12)], 10).is_none());
        let mut op = vec![0.5; 4];
        let mut lo = vec![0.25; 4];
        l.hide(2, &mut op, &mut lo);
        assert_eq!(op, vec![0.5, HIDDEN_OPACITY, 0.5, HIDDEN_OPACITY]);
        assert_eq!(lo, vec![0.25, HIDDEN_OPACITY, 0.25, HIDDEN_OPACITY]);
        let mut op = vec![0.5; 4];
        l.hide(7, &mut op, &mut []);
        assert_eq!(op, vec![0.5, 0.5, HIDDEN_OPACITY, HIDDEN_OPACITY]);
        assert_eq!(l.shown(7, 4), 2);
        assert_eq!(crate::model::sigmoid(HIDDEN_OPACITY), 0.0);
    }
}
