//! The shapes of a binary-voxel residual field (`RNTC`, format-spec §6.6.2) and its MLP, and
//! the grid encoder's constants: what both the plain evaluation (`ntc`) and the SIMD lanes
//! (`ntc_lanes`) read.

/// Hash primes of the grid encoder, per dimension.
pub const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];
/// Planes in their storage order, as (first axis, second axis).
pub const PLANES: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];
/// Added to the sum of kept corner weights before dividing.
pub const WEIGHT_EPS: f32 = 1e-9;

/// Shapes of the binary grids.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NtcConfig {
    /// Resolution of each plane level (reference: 512, 1024, 2048, 4096).
    pub resolutions: Vec<u32>,
    /// Features per plane entry (reference: 4).
    pub features: u8,
    /// log2 of the entries per plane level (reference: 15).
    pub log2_table: u8,
    /// Resolution of the 3D gate grid (reference: 514); one level, one feature.
    pub gate_resolution: u32,
    /// log2 of the gate grid's entries (reference: 15).
    pub gate_log2_table: u8,
}

impl Default for NtcConfig {
    fn default() -> Self {
        NtcConfig {
            resolutions: vec![512, 1024, 2048, 4096],
            features: 4,
            log2_table: 15,
            gate_resolution: 514,
            gate_log2_table: 15,
        }
    }
}

impl NtcConfig {
    pub fn levels(&self) -> usize {
        self.resolutions.len()
    }
    pub fn table(&self) -> usize {
        1 << self.log2_table
    }
    pub fn gate_table(&self) -> usize {
        1 << self.gate_log2_table
    }
    /// Width of the MLP input: planes x levels x features.
    pub fn input_width(&self) -> usize {
        3 * self.levels() * self.features as usize
    }
    /// Bits in one plane level.
    pub fn level_bits(&self) -> usize {
        self.table() * self.features as usize
    }
}

/// `Linear(in -> hidden) + ReLU + Linear(hidden -> out)`, with biases, PyTorch layout
/// (`w1[j * in + i]`).
#[derive(Debug, Clone, PartialEq)]
pub struct NtcMlp {
    pub inputs: usize,
    pub hidden: usize,
    pub outputs: usize,
    pub w1: Vec<f32>,
    pub b1: Vec<f32>,
    pub w2: Vec<f32>,
    pub b2: Vec<f32>,
}

impl NtcMlp {
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.w1.len() != self.inputs * self.hidden
            || self.b1.len() != self.hidden
            || self.w2.len() != self.hidden * self.outputs
            || self.b2.len() != self.outputs
        {
            return Err(format!(
                "MLP weights do not match {} -> {} -> {}",
                self.inputs, self.hidden, self.outputs
            ));
        }
        Ok(())
    }
    pub fn params(&self) -> impl Iterator<Item = &f32> {
        self.w1
            .iter()
            .chain(&self.b1)
            .chain(&self.w2)
            .chain(&self.b2)
    }
}
