//! The deformation field of one GOP: key time features and the bias-free MLP decoders
//! (format-spec/dlgs.md §6.2–§6.4, formulas in §6.4).

use crate::container::SceneHeader;
use crate::error::{Error, Result};

/// Key time features of the dynamic Gaussians, laid out like the reference's `(N, K, C)`
/// tensor: `data[(i * keys + k) * channels + c]`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TimeFeatures {
    pub n: usize,
    pub keys: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl TimeFeatures {
    pub fn zeros(n: usize, keys: usize, channels: usize) -> Self {
        TimeFeatures {
            n,
            keys,
            channels,
            data: vec![0.0; n * keys * channels],
        }
    }
    /// The `channels` values of Gaussian `i` at key `k`.
    pub fn at(&self, i: usize, k: usize) -> &[f32] {
        let o = (i * self.keys + k) * self.channels;
        &self.data[o..o + self.channels]
    }
    pub fn at_mut(&mut self, i: usize, k: usize) -> &mut [f32] {
        let o = (i * self.keys + k) * self.channels;
        &mut self.data[o..o + self.channels]
    }
    /// Keep only the keys listed (e.g. every 2nd key for a sparser key interval).
    pub fn select_keys(&self, keys: &[usize]) -> TimeFeatures {
        let mut out = TimeFeatures::zeros(self.n, keys.len(), self.channels);
        for i in 0..self.n {
            for (j, &k) in keys.iter().enumerate() {
                out.at_mut(i, j).copy_from_slice(self.at(i, k));
            }
        }
        out
    }
}

/// Which decoder an MLP is; fixes its input routing and how its output is applied (§6.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MlpRole {
    /// `F[0:12]` of one key -> `[Δxyz(3), tangent(3)]`.
    Deform = 0,
    /// `F[0:12]` of one key -> `[Δlog-scale(3), Δquat(4)]`.
    Cov = 1,
    /// `lerp(F[4:12]) ‖ view dir(3) ‖ distance(1)` -> tanh Δ pre-sigmoid opacity [colour, language].
    Opacity = 2,
    /// Same input -> ΔSH for the first `out/3` coefficients, coefficient-major.
    Color = 3,
    /// `lerp(F[8:16])` -> Δ language feature.
    Lang = 4,
}

impl MlpRole {
    pub const ALL: [MlpRole; 5] = [
        MlpRole::Deform,
        MlpRole::Cov,
        MlpRole::Opacity,
        MlpRole::Color,
        MlpRole::Lang,
    ];
    pub fn from_u8(v: u8) -> Option<Self> {
        Self::ALL.get(v as usize).copied()
    }
    pub fn name(self) -> &'static str {
        match self {
            MlpRole::Deform => "deform",
            MlpRole::Cov => "cov",
            MlpRole::Opacity => "opacity",
            MlpRole::Color => "color",
            MlpRole::Lang => "lang",
        }
    }
    /// Input width the routing gives this role (time features have 16 channels).
    pub fn inputs(self) -> usize {
        match self {
            MlpRole::Lang => 8,
            _ => 12,
        }
    }
    /// Whether the last layer is followed by tanh (the reference's opacity decoder).
    pub fn output_tanh(self) -> bool {
        self == MlpRole::Opacity
    }
}

/// One bias-free linear layer, PyTorch layout: `weights[o * inputs + i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    pub inputs: usize,
    pub outputs: usize,
    pub weights: Vec<f32>,
}

/// Linear layers with ReLU between them (none after the last; tanh after it for `Opacity`).
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    pub role: MlpRole,
    pub layers: Vec<Layer>,
}

impl Mlp {
    pub fn inputs(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inputs)
    }
    pub fn outputs(&self) -> usize {
        self.layers.last().map_or(0, |l| l.outputs)
    }
    pub fn weight_count(&self) -> usize {
        self.layers.iter().map(|l| l.weights.len()).sum()
    }
    /// Multiply-adds per evaluated row.
    pub fn macs(&self) -> usize {
        self.layers.iter().map(|l| l.inputs * l.outputs).sum()
    }
}

/// The decoders of one GOP.
#[derive(Debug, Clone, PartialEq)]
pub struct DeformMlps {
    pub deform: Mlp,
    pub cov: Mlp,
    pub opacity: Mlp,
    pub color: Mlp,
    /// Present when the scene has language.
    pub lang: Option<Mlp>,
    /// Apply `mlp_cov`'s log-scale offsets (the reference does so from GOP 1 on; GOP 0 keeps
    /// the canonical scales).
    pub scale_offsets: bool,
}

impl DeformMlps {
    pub fn iter(&self) -> impl Iterator<Item = &Mlp> {
        [&self.deform, &self.cov, &self.opacity, &self.color]
            .into_iter()
            .chain(self.lang.as_ref())
    }

    /// Shapes the scene requires (§6.3 table). `at` is reported in errors.
    pub fn validate(&self, scene: &SceneHeader, at: u64) -> Result<()> {
        let bad = |reason: String| Error::payload(crate::container::ChunkType::MLPW, reason, at);
        if scene.time_channels != 16 {
            return Err(bad(format!(
                "the decoders' channel routing needs 16 time channels, HEAD has {}",
                scene.time_channels
            )));
        }
        if (scene.lang_width() > 0) != self.lang.is_some() {
            return Err(bad(format!(
                "language MLP {} but the scene has language width {}",
                if self.lang.is_some() {
                    "present"
                } else {
                    "absent"
                },
                scene.lang_width()
            )));
        }
        for m in self.iter() {
            if m.layers.is_empty() {
                return Err(bad(format!("{} MLP has no layers", m.role.name())));
            }
            for w in m.layers.windows(2) {
                if w[0].outputs != w[1].inputs {
                    return Err(bad(format!(
                        "{} MLP layer widths do not chain",
                        m.role.name()
                    )));
                }
            }
            for l in &m.layers {
                if l.weights.len() != l.inputs * l.outputs {
                    return Err(bad(format!("{} MLP weight count", m.role.name())));
                }
            }
            if m.inputs() != m.role.inputs() {
                return Err(bad(format!(
                    "{} MLP takes {} inputs, the routing gives {}",
                    m.role.name(),
                    m.inputs(),
                    m.role.inputs()
                )));
            }
            let coeffs = crate::model::sh_coeffs(scene.sh_degree);
            let out_ok = match m.role {
                MlpRole::Deform => m.outputs() == 6,
                MlpRole::Cov => m.outputs() == 7,
                MlpRole::Opacity => m.outputs() == 1 || m.outputs() == 2,
                MlpRole::Color => {
                    m.outputs() % 3 == 0 && m.outputs() >= 3 && m.outputs() / 3 <= coeffs
                }
                MlpRole::Lang => m.outputs() == scene.lang_width(),
            };
            if !out_ok {
                return Err(bad(format!(
                    "{} MLP has {} outputs, which the scene does not allow",
                    m.role.name(),
                    m.outputs()
                )));
            }
        }
        Ok(())
    }

    /// Multiply-adds per dynamic Gaussian per frame for the view-dependent and language parts
    /// (what `frame_at` recomputes every frame; geometry is per key, once per GOP).
    pub fn per_frame_macs(&self, language: bool) -> usize {
        self.opacity.macs()
            + self.color.macs()
            + if language {
                self.lang.as_ref().map_or(0, |m| m.macs())
            } else {
                0
            }
    }
}

/// Everything that animates the dynamic Gaussians of one GOP.
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicGop {
    pub features: TimeFeatures,
    pub mlps: DeformMlps,
    /// Gaussians shown for only part of the GOP (`LIFE`, §6.14); `None`: all at every frame.
    pub life: Option<crate::model::Lifetimes>,
}

/// Reject NaN/Inf before anything is written (the encoder's promise in §6).
pub fn check_finite(what: &str, v: &[f32]) -> Result<()> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(Error::input(format!(
            "{what}: value {} at index {i} is not finite",
            v[i]
        )));
    }
    Ok(())
}

/// Where time `t` falls: GOP, key pair and the fraction between the two keys (§4.3, §6.4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimePoint {
    pub gop: u32,
    /// Index of the earlier key; the later one is `key + 1`.
    pub key: usize,
    /// Fraction in [0, 1] between the two keys.
    pub delta: f32,
    /// The frame index shown at `t`.
    pub frame: u32,
    /// `frame`'s place in its GOP (`frame - gop × gop_length`): what `LIFE` (§6.14) compares.
    pub local_frame: u32,
}

impl SceneHeader {
    /// Locate time `t` seconds (`0 <= t <= frame_count / fps`). Times within 1e-6 frames of a
    /// frame time snap to it, so frame times give exactly the reference's `(t_idx, delta_t)`.
    pub fn locate(&self, t: f64) -> Result<TimePoint> {
        if !t.is_finite() || t < 0.0 || t > self.duration_seconds() {
            return Err(Error::request(format!(
                "time {t} s outside the stream [0, {:.4}] s",
                self.duration_seconds()
            )));
        }
        let mut u = t * self.fps();
        if (u - u.round()).abs() < 1e-6 {
            u = u.round();
        }
        let gl = self.gop_length as f64;
        let gop = ((u / gl).floor() as u64).min(self.gop_count as u64 - 1) as u32;
        let local = (u - gop as f64 * gl).clamp(0.0, gl);
        let iv = self.key_interval as f64;
        let last_pair = self.keys_per_gop() as usize - 2;
        let key = ((local / iv).floor() as usize).min(last_pair);
        let delta = ((local - key as f64 * iv) / iv).clamp(0.0, 1.0) as f32;
        let frame = (u.floor() as u64).min(self.frame_count as u64 - 1) as u32;
        Ok(TimePoint {
            gop,
            key,
            delta,
            frame,
            local_frame: frame.saturating_sub(gop * self.gop_length),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> SceneHeader {
        let mut s = SceneHeader::still(1, 0);
        s.gop_length = 60;
        s.key_interval = 10;
        s.gop_count = 2;
        s.frame_count = 120;
        s
    }

    #[test]
    fn frame_times_match_the_reference_lookup() {
        let s = scene();
        for f in 0..120u32 {
            let p = s.locate(f as f64 / 30.0).unwrap();
            let local = f % 60;
            assert_eq!(p.gop, f / 60);
            assert_eq!(p.key, (local / 10) as usize);
            assert_eq!(p.delta, (local % 10) as f32 / 10.0, "frame {f}");
            assert_eq!(p.frame, f);
        }
    }

    #[test]
    fn between_frames_and_the_end() {
        let s = scene();
        let p = s.locate(0.5 / 30.0).unwrap();
        assert_eq!((p.gop, p.key, p.frame), (0, 0, 0));
        assert!((p.delta - 0.05).abs() < 1e-6);
        let end = s.locate(4.0).unwrap();
        assert_eq!((end.gop, end.key, end.delta, end.frame), (1, 5, 1.0, 119));
        assert!(s.locate(4.0001).is_err());
        assert!(s.locate(-0.0001).is_err());
        assert!(s.locate(f64::NAN).is_err());
    }
}
