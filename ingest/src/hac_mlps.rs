//! The reference's HAC (Scaffold-GS) `png_quant/mlps.pth`: a dict of the MLPs' state_dicts
//! (`Sequential(Linear, ReLU, Linear[, activation])`, keys `0.weight`, `0.bias`, `2.weight`,
//! `2.bias`) and the anchor bounds `x_bound_min`, `x_bound_max` (1, 3).
//!
//! GOP 0 holds all of them; a later GOP with an NTC residual holds only the deformation MLPs,
//! `mlp_language` and the bounds (the view MLPs are GOP 0's).

use std::path::Path;

use dlgs::model::scaffold::{
    Activation, AnchorDeformMlps, Dense, ScaffoldMlps, TwoLayer, VIEW_INPUTS,
};

use crate::torch::{read_zip_nested, Tensor};
use crate::IngestError;

/// What one `mlps.pth` holds.
#[derive(Debug, Clone, PartialEq)]
pub struct HacMlps {
    pub bounds: ([f32; 3], [f32; 3]),
    pub deform: AnchorDeformMlps,
    /// `mlp_opacity`, `mlp_color`, `mlp_cov` (GOP 0 only).
    pub opacity: Option<TwoLayer>,
    pub color: Option<TwoLayer>,
    pub cov: Option<TwoLayer>,
    pub language: Option<TwoLayer>,
    /// The context model's `mlp_grid` (GOP 0 only).
    pub grid: Option<TwoLayer>,
    /// The NTC's `ntc_mlp` (48 -> 100 -> 80; GOPs with an NTC residual).
    pub ntc: Option<TwoLayer>,
}

impl HacMlps {
    /// The view MLPs of this file, with `language` taken from `language_of` when given (a later
    /// GOP's own `mlp_language` with GOP 0's other view MLPs).
    pub fn view_mlps(&self, language_of: Option<&HacMlps>) -> Option<ScaffoldMlps> {
        let m = ScaffoldMlps {
            opacity: self.opacity.clone()?,
            color: self.color.clone()?,
            cov: self.cov.clone()?,
            language: language_of.unwrap_or(self).language.clone(),
        };
        m.check().ok()?;
        Some(m)
    }
}

fn two_layer(
    t: &[(String, Tensor)],
    name: &str,
    output: Activation,
    what: &str,
) -> Result<Option<TwoLayer>, IngestError> {
    let get = |k: &str| {
        t.iter()
            .find(|(n, _)| n == &format!("{name}.{k}"))
            .map(|(_, v)| v)
    };
    let Some(w0) = get("0.weight") else {
        return Ok(None);
    };
    let w2 = get("2.weight")
        .ok_or_else(|| IngestError::format(what, format!("{name} has no 2.weight")))?;
    let dense = |w: &Tensor, b: Option<&Tensor>, k: &str| -> Result<Dense, IngestError> {
        let label = format!("{what}: {name}.{k}");
        if w.shape.len() != 2 {
            return Err(IngestError::shape(&label, format!("{:?}", w.shape)));
        }
        let bias = b.map(|b| b.f32s(&label)).transpose()?;
        if bias.as_ref().is_some_and(|v| v.len() != w.shape[0]) {
            return Err(IngestError::shape(&label, "bias length"));
        }
        Ok(Dense {
            inputs: w.shape[1],
            outputs: w.shape[0],
            weights: w.f32s(&label)?,
            bias,
        })
    };
    Ok(Some(TwoLayer {
        first: dense(w0, get("0.bias"), "0")?,
        second: dense(w2, get("2.bias"), "2")?,
        output,
    }))
}

/// Read one `mlps.pth`.
pub fn read_hac_mlps(path: &Path) -> Result<HacMlps, IngestError> {
    let what = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| IngestError::Io {
        what: what.clone(),
        source,
    })?;
    let t = read_zip_nested(std::io::Cursor::new(bytes), &what)?;
    let bound = |k: &str| -> Result<[f32; 3], IngestError> {
        let v = t
            .iter()
            .find(|(n, _)| n == k)
            .ok_or_else(|| IngestError::format(&what, format!("no {k}")))?
            .1
            .f32s(&what)?;
        <[f32; 3]>::try_from(v.as_slice())
            .map_err(|_| IngestError::shape(&what, format!("{k} is not 3 values")))
    };
    let need = |m: Option<TwoLayer>, name: &str| {
        m.ok_or_else(|| IngestError::format(&what, format!("no {name}")))
    };
    let id = Activation::Identity;
    let deform = AnchorDeformMlps {
        position: need(
            two_layer(&t, "mlp_deform_xyz", id, &what)?,
            "mlp_deform_xyz",
        )?,
        feature: need(
            two_layer(&t, "mlp_deform_cov", id, &what)?,
            "mlp_deform_cov",
        )?,
        offsets: need(
            two_layer(&t, "mlp_deform_opacity", id, &what)?,
            "mlp_deform_opacity",
        )?,
        scaling: need(
            two_layer(&t, "mlp_deform_color", id, &what)?,
            "mlp_deform_color",
        )?,
    };
    deform.check().map_err(|r| IngestError::format(&what, r))?;
    let out = HacMlps {
        bounds: (bound("x_bound_min")?, bound("x_bound_max")?),
        deform,
        opacity: two_layer(&t, "mlp_opacity", Activation::Tanh, &what)?,
        color: two_layer(&t, "mlp_color", Activation::Sigmoid, &what)?,
        cov: two_layer(&t, "mlp_cov", id, &what)?,
        language: two_layer(&t, "mlp_language", id, &what)?,
        grid: two_layer(&t, "mlp_grid", id, &what)?,
        ntc: two_layer(&t, "ntc_mlp", id, &what)?,
    };
    for m in [&out.opacity, &out.color, &out.cov, &out.language]
        .into_iter()
        .flatten()
    {
        if m.first.inputs != VIEW_INPUTS {
            return Err(IngestError::shape(
                &what,
                format!(
                    "a view MLP takes {} inputs, not {VIEW_INPUTS}",
                    m.first.inputs
                ),
            ));
        }
    }
    Ok(out)
}
