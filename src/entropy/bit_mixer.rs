//! Logistic mixing of binary predictions (format-spec §6.5.3, codec 5 mode 5): several
//! adaptive models predict the same bit, each from its own context, and a small online
//! learner weighs their log-odds. A context that predicts well for this channel earns weight,
//! one that is too sparse to have learned anything loses it, so adding a context never costs
//! much. Integer arithmetic only: the encoder and every decoder compute the same bits.

/// The logistic function `4096 / (1 + e^(-x/256))` at `x = -2048, -1920, .., 2048`, rounded;
/// [`squash`] interpolates between these knots.
const SQUASH_KNOTS: [i32; 33] = [
    1, 2, 4, 6, 10, 17, 27, 45, 74, 120, 194, 311, 488, 747, 1102, 1546, 2048, 2550, 2994, 3349,
    3608, 3785, 3902, 3976, 4022, 4051, 4069, 4079, 4086, 4090, 4092, 4094, 4095,
];

/// Log-odds `d` (units of 1/256) to a 12-bit probability in `[1, 4095]`: the knots of
/// [`SQUASH_KNOTS`] joined by straight lines, `4095` from 2047 up and `1` from -2047 down.
#[inline]
pub fn squash(d: i32) -> i32 {
    SQUASH[(d.clamp(-2047, 2047) + 2047) as usize] as i32
}

/// [`squash`] at every `d` in `[-2047, 2047]`.
static SQUASH: [i16; 4095] = build_squash();

/// At `d + 2047` for every `d` in `[-2047, 2047]`: `squash(d)` in the low 16 bits, and in the
/// high 16 the coder's 16-bit probability of codec 5 modes 5-6, `(squash(d) << 4)` kept in
/// `[32, 65504]` (format-spec §6.5.3): both from one load in the decoder's loop.
pub(crate) static SQUASH_AND_P16: [u32; 4095] = build_squash_and_p16();

const fn build_squash_and_p16() -> [u32; 4095] {
    let mut t = [0u32; 4095];
    let mut d = -2047i32;
    while d <= 2047 {
        let p12 = squash_const(d) as u32;
        let mut p16 = p12 << 4;
        if p16 < 32 {
            p16 = 32;
        }
        if p16 > 65504 {
            p16 = 65504;
        }
        t[(d + 2047) as usize] = p12 | p16 << 16;
        d += 1;
    }
    t
}

const fn build_squash() -> [i16; 4095] {
    let mut t = [0i16; 4095];
    let mut d = -2047i32;
    while d <= 2047 {
        t[(d + 2047) as usize] = squash_const(d) as i16;
        d += 1;
    }
    t
}

/// `STRETCH[p]` = the smallest `d` in `[-2047, 2047]` with `squash(d) >= p` (2047 when none):
/// the inverse of [`squash`], built by a walk over `d` at compile time.
static STRETCH: [i16; 4096] = build_stretch();

const fn squash_const(d: i32) -> i32 {
    if d >= 2047 {
        return 4095;
    }
    if d <= -2047 {
        return 1;
    }
    let w = d & 127;
    let k = ((d >> 7) + 16) as usize;
    (SQUASH_KNOTS[k] * (128 - w) + SQUASH_KNOTS[k + 1] * w + 64) >> 7
}

const fn build_stretch() -> [i16; 4096] {
    let mut t = [0i16; 4096];
    let mut p = 0usize;
    let mut d = -2047i32;
    while d <= 2047 {
        let v = squash_const(d) as usize;
        while p <= v {
            t[p] = d as i16;
            p += 1;
        }
        d += 1;
    }
    while p < 4096 {
        t[p] = 2047;
        p += 1;
    }
    t
}

/// `stretch(p16 >> 4) << 3` at every `p16 >> 4` (the log-odds of a 16-bit probability, in
/// the units of [`stretch`] times 8: the decoder of codec 5 modes 5-6 keeps 3 more bits of
/// a model beside it).
pub(crate) static STRETCH_X8: [i16; 4096] = build_stretch_x8();

const fn build_stretch_x8() -> [i16; 4096] {
    let mut t = build_stretch();
    let mut i = 0;
    while i < 4096 {
        t[i] <<= 3;
        i += 1;
    }
    t
}

/// 12-bit probability to log-odds (units of 1/256, `[-2047, 2047]`).
#[inline]
pub fn stretch(p12: u32) -> i32 {
    STRETCH[(p12 as usize).min(4095)] as i32
}

/// Log-odds of the constant bias input.
pub(crate) const BIAS: i32 = 256;
/// Learning rate: a weight moves `err * input >> LEARNING_SHIFT` (weights in 1/65536).
pub(crate) const LEARNING_SHIFT: u32 = 10;
/// Weights stay in `[-WEIGHT_LIMIT, WEIGHT_LIMIT]`.
pub(crate) const WEIGHT_LIMIT: i32 = 1 << 22;

/// One weight vector per selector value (codec 5 mode 5: the tree level), each over `N`
/// log-odds: `N - 1` model predictions and the bias, last.
pub struct Mixer<const N: usize> {
    weights: Vec<[i32; N]>,
    /// The last prediction's inputs, selector and output, for [`Mixer::update`].
    st: [i32; N],
    selected: usize,
    p: i32,
}

impl<const N: usize> Mixer<N> {
    /// `selectors` weight vectors; every model starts with weight `1 / (N - 1)`, the bias
    /// with 0.
    pub fn new(selectors: usize) -> Mixer<N> {
        assert!(N >= 2, "at least one model and the bias");
        let mut w = [65536 / (N as i32 - 1); N];
        w[N - 1] = 0;
        Mixer {
            weights: vec![w; selectors.max(1)],
            st: [0; N],
            selected: 0,
            p: 2048,
        }
    }

    /// The mixed 12-bit probability of a 0 bit from the `N - 1` models' 16-bit probabilities
    /// of a 0 bit (`p0[N - 1]` is ignored), with weight vector `selector`.
    #[inline]
    pub fn predict(&mut self, p0: [u16; N], selector: usize) -> u32 {
        self.selected = selector.min(self.weights.len() - 1);
        for j in 0..N - 1 {
            self.st[j] = stretch(p0[j] as u32 >> 4);
        }
        self.st[N - 1] = BIAS;
        let w = &self.weights[self.selected];
        let mut dot = 0i64;
        for j in 0..N {
            dot += w[j] as i64 * self.st[j] as i64;
        }
        self.p = squash((dot >> 16).clamp(-2047, 2047) as i32);
        self.p as u32
    }

    /// Learn from the coded bit: each weight moves along its input by the prediction's error.
    #[inline]
    pub fn update(&mut self, bit: bool) {
        let target = if bit { 0 } else { 4095 };
        let err = target - self.p;
        let w = &mut self.weights[self.selected];
        for j in 0..N {
            w[j] =
                (w[j] + ((self.st[j] * err) >> LEARNING_SHIFT)).clamp(-WEIGHT_LIMIT, WEIGHT_LIMIT);
        }
    }
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // the platform libm as a reference or test data
mod tests {
    use super::*;

    #[test]
    fn stretch_inverts_squash_and_both_are_monotone() {
        let mut last = 0;
        for d in -2047..=2047 {
            let p = squash(d);
            assert!(p >= last && (1..=4095).contains(&p));
            last = p;
            // The smallest d reaching p is at most this d, and reaches p.
            let s = stretch(p as u32);
            assert!(s <= d && squash(s) >= p, "d {d} p {p} s {s}");
        }
        assert_eq!(squash(0), 2048);
        assert_eq!((stretch(0), stretch(1), stretch(2048)), (-2047, -2047, 0));
    }

    #[test]
    fn the_mixer_learns_to_trust_the_model_that_predicts() {
        // Model 0 knows the bit (p0 = 0.95 when the bit is 0), model 1 says 1/2 always.
        let mut m = Mixer::<3>::new(1);
        let mut s = 12345u32;
        let mut cost = 0.0f64;
        for step in 0..4000 {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            let bit = s.is_multiple_of(3);
            let good = if bit { 3277u16 } else { 62259 };
            let p = m.predict([good, 32768, 0], 0) as f64 / 4096.0;
            if step >= 3000 {
                cost -= if bit { 1.0 - p } else { p }.log2();
            }
            m.update(bit);
        }
        // The ideal is the informed model's cost, -log2(0.95) = 0.074 bit; a mixer stuck at
        // the starting weights would pay far more.
        assert!(cost / 1000.0 < 0.1, "{} bits per bit", cost / 1000.0);
    }
}
