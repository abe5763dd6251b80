//! The Scaffold-GS variant's model (the reference's `--type hac`; ../shared/reference §1.3-1.4,
//! §5.2): anchors that carry a feature, offsets and scalings, from which small MLPs generate
//! "neural Gaussians" for each view, and the bias-free MLPs that deform dynamic anchors from
//! interpolated time features.
//!
//! Only the data and its checks live here; generating a view's Gaussians and deforming
//! anchors at a time are decode work (`dlgs-decoder`'s `scaffold`).

/// Child Gaussians per anchor (`n_offsets`).
pub const N_OFFSETS: usize = 10;
/// Anchor feature width (`feat_dim`).
pub const FEAT_DIM: usize = 50;
/// Log-scalings per anchor: 3 scale the offsets, 3 the children's scales.
pub const SCALING_DIM: usize = 6;
/// Inputs of the view-dependent MLPs: feature, view direction, distance.
pub const VIEW_INPUTS: usize = FEAT_DIM + 4;
/// Language feature width per child.
pub const LANG_DIM: usize = 9;
/// Time-feature channels of a dynamic anchor.
pub const TIME_CHANNELS: usize = 16;

/// A set of anchors, row-major per attribute.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Anchors {
    pub positions: Vec<[f32; 3]>,
    /// `FEAT_DIM` per anchor.
    pub features: Vec<f32>,
    /// `N_OFFSETS * 3` per anchor, offset-major (`offsets[(a * N_OFFSETS + k) * 3 + d]`).
    pub offsets: Vec<f32>,
    /// `SCALING_DIM` per anchor, natural log.
    pub log_scalings: Vec<f32>,
}

impl Anchors {
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    /// Every attribute has one row per anchor.
    pub fn check_shapes(&self) -> std::result::Result<(), String> {
        let n = self.len();
        if self.features.len() != n * FEAT_DIM
            || self.offsets.len() != n * N_OFFSETS * 3
            || self.log_scalings.len() != n * SCALING_DIM
        {
            return Err(format!(
                "anchor attributes do not match {n} anchors ({} features, {} offsets, {} \
                 scalings)",
                self.features.len(),
                self.offsets.len(),
                self.log_scalings.len()
            ));
        }
        Ok(())
    }
    pub fn feature(&self, a: usize) -> &[f32] {
        &self.features[a * FEAT_DIM..(a + 1) * FEAT_DIM]
    }
    pub fn offset(&self, a: usize) -> &[f32] {
        &self.offsets[a * N_OFFSETS * 3..(a + 1) * N_OFFSETS * 3]
    }
    pub fn log_scaling(&self, a: usize) -> &[f32] {
        &self.log_scalings[a * SCALING_DIM..(a + 1) * SCALING_DIM]
    }
}

/// One attribute group of an anchor, in the order an `RNTC` residual row of a Scaffold-GS
/// scene uses (format-spec §6.6.1, since 1.17). Positions are not a group: the field is
/// evaluated at them, and every GOP of a residual chain keeps GOP 0's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AnchorGroup {
    /// The 50-value feature.
    Feature = 0,
    /// The 10 offsets, x, y, z each, as `ANCR` stores them.
    Offsets = 1,
    /// The 6 log-scalings.
    LogScaling = 2,
}

impl AnchorGroup {
    pub const ALL: [AnchorGroup; 3] = [
        AnchorGroup::Feature,
        AnchorGroup::Offsets,
        AnchorGroup::LogScaling,
    ];
    /// The mask bits an anchor residual may set.
    pub const MASK: u8 = 0b111;

    pub fn bit(self) -> u8 {
        1 << self as u8
    }
    pub fn name(self) -> &'static str {
        match self {
            AnchorGroup::Feature => "feature",
            AnchorGroup::Offsets => "offsets",
            AnchorGroup::LogScaling => "log_scaling",
        }
    }
    pub fn width(self) -> usize {
        match self {
            AnchorGroup::Feature => FEAT_DIM,
            AnchorGroup::Offsets => 3 * N_OFFSETS,
            AnchorGroup::LogScaling => SCALING_DIM,
        }
    }
    /// The groups a mask selects, ascending (undefined bits are skipped).
    pub fn selected(mask: u8) -> impl Iterator<Item = AnchorGroup> {
        Self::ALL.into_iter().filter(move |g| mask & g.bit() != 0)
    }
    /// The group's values of anchor `i`.
    pub fn values_mut(self, a: &mut Anchors, i: usize) -> &mut [f32] {
        let w = self.width();
        let v = match self {
            AnchorGroup::Feature => &mut a.features,
            AnchorGroup::Offsets => &mut a.offsets,
            AnchorGroup::LogScaling => &mut a.log_scalings,
        };
        &mut v[i * w..(i + 1) * w]
    }
}

/// What follows a dense layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activation {
    Identity,
    Relu,
    Tanh,
    Sigmoid,
}

/// A linear layer, PyTorch layout (`weights[o * inputs + i]`), with or without bias.
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    pub inputs: usize,
    pub outputs: usize,
    pub weights: Vec<f32>,
    pub bias: Option<Vec<f32>>,
}

/// `Linear -> ReLU -> Linear -> activation` (every MLP of this variant has this shape).
#[derive(Debug, Clone, PartialEq)]
pub struct TwoLayer {
    pub first: Dense,
    pub second: Dense,
    pub output: Activation,
}

impl TwoLayer {
    pub fn inputs(&self) -> usize {
        self.first.inputs
    }
    pub fn outputs(&self) -> usize {
        self.second.outputs
    }
    /// Shapes agree, every weight is finite, biases are present or absent as `biased` says.
    pub fn check(
        &self,
        name: &str,
        inputs: usize,
        outputs: usize,
        biased: bool,
    ) -> Result<(), String> {
        let (a, b) = (&self.first, &self.second);
        let dense_ok = |d: &Dense| {
            d.weights.len() == d.inputs * d.outputs
                && d.bias.as_ref().is_none_or(|v| v.len() == d.outputs)
                && d.bias.is_some() == biased
        };
        if a.inputs != inputs
            || b.outputs != outputs
            || a.outputs != b.inputs
            || !dense_ok(a)
            || !dense_ok(b)
        {
            return Err(format!(
                "{name}: expected {inputs} -> h -> {outputs}{}, got {} -> {} -> {}",
                if biased {
                    " with biases"
                } else {
                    " without biases"
                },
                a.inputs,
                a.outputs,
                b.outputs
            ));
        }
        let finite = |d: &Dense| {
            d.weights
                .iter()
                .chain(d.bias.iter().flatten())
                .all(|v| v.is_finite())
        };
        if !finite(a) || !finite(b) {
            return Err(format!("{name}: weights must be finite"));
        }
        Ok(())
    }
}

/// The view-dependent decoders (with biases), shared by every GOP (trained in GOP 0).
#[derive(Debug, Clone, PartialEq)]
pub struct ScaffoldMlps {
    /// 54 -> 50 -> 20 (colour and language opacity per child, interleaved), tanh; 54 -> 50 -> 10
    /// without language.
    pub opacity: TwoLayer,
    /// 54 -> 50 -> 30, sigmoid: RGB per child.
    pub color: TwoLayer,
    /// 54 -> 50 -> 70: per child 3 scale factors (through a sigmoid) and a raw quaternion.
    pub cov: TwoLayer,
    /// 54 -> 50 -> 90: 9 language values per child.
    pub language: Option<TwoLayer>,
}

impl ScaffoldMlps {
    pub fn check(&self) -> Result<(), String> {
        let lang = self.language.is_some();
        let opacities = if lang { 2 * N_OFFSETS } else { N_OFFSETS };
        self.opacity
            .check("mlp_opacity", VIEW_INPUTS, opacities, true)?;
        self.color
            .check("mlp_color", VIEW_INPUTS, 3 * N_OFFSETS, true)?;
        self.cov
            .check("mlp_cov", VIEW_INPUTS, 7 * N_OFFSETS, true)?;
        if let Some(l) = &self.language {
            l.check("mlp_language", VIEW_INPUTS, LANG_DIM * N_OFFSETS, true)?;
        }
        let acts = [
            (&self.opacity, Activation::Tanh),
            (&self.color, Activation::Sigmoid),
            (&self.cov, Activation::Identity),
        ];
        if acts.iter().any(|(m, a)| m.output != *a)
            || self
                .language
                .as_ref()
                .is_some_and(|l| l.output != Activation::Identity)
        {
            return Err("output activations must be tanh, sigmoid, none, none".into());
        }
        Ok(())
    }
}

/// The four bias-free anchor deformation MLPs of one GOP (§5.2; their names are historical).
#[derive(Debug, Clone, PartialEq)]
pub struct AnchorDeformMlps {
    /// `mlp_deform_xyz`: 19 (time features, normalised anchor) -> 64 -> 3, added to the position.
    pub position: TwoLayer,
    /// `mlp_deform_cov`: 16 -> 128 -> 50, added to the feature.
    pub feature: TwoLayer,
    /// `mlp_deform_opacity`: 16 -> 64 -> 30, added to the offsets.
    pub offsets: TwoLayer,
    /// `mlp_deform_color`: 16 -> 64 -> 6, added to the log-scalings.
    pub scaling: TwoLayer,
}

impl AnchorDeformMlps {
    pub fn check(&self) -> Result<(), String> {
        self.position
            .check("mlp_deform_xyz", TIME_CHANNELS + 3, 3, false)?;
        self.feature
            .check("mlp_deform_cov", TIME_CHANNELS, FEAT_DIM, false)?;
        self.offsets
            .check("mlp_deform_opacity", TIME_CHANNELS, 3 * N_OFFSETS, false)?;
        self.scaling
            .check("mlp_deform_color", TIME_CHANNELS, SCALING_DIM, false)?;
        for m in [&self.position, &self.feature, &self.offsets, &self.scaling] {
            if m.output != Activation::Identity {
                return Err("deformation MLPs have no output activation".into());
            }
        }
        Ok(())
    }
}

/// One GOP's canonical anchors: static, then dynamic.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScaffoldCanonical {
    pub statics: Anchors,
    pub dynamics: Anchors,
}

/// One GOP's anchor deformation: bounds of the normalised anchor and the four MLPs.
#[derive(Debug, Clone, PartialEq)]
pub struct AnchorDeformation {
    /// `x_bound_min`, `x_bound_max`: `norm_anchor = (a - min) / (max - min)`.
    pub bound_min: [f32; 3],
    pub bound_max: [f32; 3],
    pub mlps: AnchorDeformMlps,
}

/// What a Scaffold-GS scene header must say (format-spec §6.12): SH degree 0 (colours come
/// from the colour MLP), intra or sequential GOPs (since 1.17; parallel is refused), the plain
/// deformation model (lerp), 16 time channels iff there are dynamic anchors, and language of 3
/// levels x 3 dims or none.
pub fn check_scene(s: &crate::container::SceneHeader) -> Result<(), String> {
    use crate::container::header::{DeformModel, ResidualMode};
    if s.sh_degree != 0 {
        return Err(format!(
            "sh_degree {} (Scaffold-GS scenes have 0)",
            s.sh_degree
        ));
    }
    if s.residual_mode == ResidualMode::Parallel {
        return Err(
            "Scaffold-GS scenes are intra or sequential (residual_mode 0 or 1), not parallel"
                .into(),
        );
    }
    if s.deform_model != DeformModel::PaperLerp {
        return Err("Scaffold-GS scenes use deform_model 1 (lerp of time features)".into());
    }
    let want = if s.n_dynamic > 0 {
        TIME_CHANNELS as u8
    } else {
        0
    };
    if s.time_channels != want {
        return Err(format!(
            "time_channels {} ({want} expected)",
            s.time_channels
        ));
    }
    if (s.lang_levels as usize * s.lang_dims as usize) != 0
        && (s.lang_levels, s.lang_dims) != (3, 3)
    {
        return Err(format!(
            "language {}x{} (3x3 or none)",
            s.lang_levels, s.lang_dims
        ));
    }
    Ok(())
}

impl ScaffoldCanonical {
    /// Static then dynamic anchors in one set, split at `n_static` (the static rows stay in
    /// place; only the dynamic ones move). `n_static` must be at most `all.len()`.
    pub fn split_at(mut all: Anchors, n_static: usize) -> ScaffoldCanonical {
        let dynamics = Anchors {
            positions: all.positions.split_off(n_static),
            features: all.features.split_off(n_static * FEAT_DIM),
            offsets: all.offsets.split_off(n_static * 3 * N_OFFSETS),
            log_scalings: all.log_scalings.split_off(n_static * SCALING_DIM),
        };
        ScaffoldCanonical {
            statics: all,
            dynamics,
        }
    }

    /// Static then dynamic anchors in one set (the inverse of [`Self::split_at`]).
    pub fn joined(&self) -> Anchors {
        let mut all = self.statics.clone();
        all.positions.extend_from_slice(&self.dynamics.positions);
        all.features.extend_from_slice(&self.dynamics.features);
        all.offsets.extend_from_slice(&self.dynamics.offsets);
        all.log_scalings
            .extend_from_slice(&self.dynamics.log_scalings);
        all
    }

    /// The canonical anchors `field` (an `RNTC` of a Scaffold-GS scene) makes of this reference
    /// state (format-spec §6.6.5, §6.12): each selected set's rows are evaluated at the
    /// reference's canonical positions and added, f32, to the selected groups; positions and
    /// everything not selected are copied. The result is the same on any thread count.
    pub fn with_residual(
        &self,
        field: &crate::model::ntc::NtcField,
    ) -> std::result::Result<ScaffoldCanonical, String> {
        use crate::model::ntc::RowLayout;
        use crate::model::residual::{SET_DYNAMIC, SET_STATIC};
        field.validate_layout(RowLayout::Anchors)?;
        self.statics.check_shapes()?;
        self.dynamics.check_shapes()?;
        let mut out = self.clone();
        let no = field.mlp.outputs;
        for (set, bit) in [
            (&mut out.statics, SET_STATIC),
            (&mut out.dynamics, SET_DYNAMIC),
        ] {
            if field.sets & bit == 0 {
                continue;
            }
            let rows = field.residuals_at(&set.positions);
            for i in 0..set.len() {
                let mut row = &rows[i * no..(i + 1) * no];
                for g in AnchorGroup::selected(field.groups) {
                    let v = g.values_mut(set, i);
                    let (d, rest) = row.split_at(v.len());
                    v.iter_mut().zip(d).for_each(|(x, d)| *x += d);
                    row = rest;
                }
            }
        }
        Ok(out)
    }
}
