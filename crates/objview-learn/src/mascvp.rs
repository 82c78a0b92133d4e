//! MA-SCVP as the reference implementation adapts it ("MASCVPPositionNet",
//! learned-baselines.md §3.3), with the grid size, channel widths and FC widths as settings
//! ([`MascvpShape`]): [`MascvpShape::reference`] is the reference shape (64³, 32/64/128/256,
//! FC 512/256/128/128, 34,184,260 parameters), [`MascvpShape::scaled`] the shape this machine
//! trains (32³ at quarter width, 8/16/32/64, same FC widths, ~1.8 M parameters) — a stated
//! deviation recorded in every sidecar and result.
//!
//! Topology (G the grid, C₀ the conv1 width, C₁..C₃ the block widths):
//! 1. conv1: Conv3d 1→C₀, k3 p1, **no activation**, max-pool 2 → C₀ × (G/2)³ ("x1");
//! 2. **view-state/position context**: per view v an MLP maps [vs_v, x_v, y_v, z_v] (the view
//!    state flag and the Tammes-128 unit vector) to 4 channels (Linear 4→64, LayerNorm,
//!    LeakyReLU 0.1, Dropout 0.1, Linear 64→64, LayerNorm, LeakyReLU 0.1, Linear 64→4), laid
//!    into the (G/2)³ volume by repeat-interleave (block v of the x-major flattened volume =
//!    token v, as in NBV-Net) and concatenated: x1 := (C₀+4) × (G/2)³;
//! 3. three SCVP blocks, each two stacks of four CNNBlocks (Conv3d k3 p1 without bias,
//!    BatchNorm3d, LeakyReLU 0.1; stack 1 maps in→out then out→out ×3, stack 2 out→out ×4),
//!    output LeakyReLU(stack2(s1) + s1) with s1 = stack1(x); each followed by a strided
//!    Conv3d k2 s2 (with bias, no activation): x2 = D1(B1(x1)), x3 = D2(B2(x2)), x4 = D3(B3(x3));
//! 4. dense skips after all three stages, in this order: x2 ← cat(x2, pool(x1)),
//!    x3 ← cat(x3, pool(x2)), x4 ← cat(x4, pool(x3)) → (C₃+C₂+C₁+C₀+4) × (G/16)³
//!    (484 × 4³ in the reference shape);
//! 5. head: flatten → FC widths (512, 256, 128, 128 in the reference) each followed by
//!    LeakyReLU 0.1 and Dropout (p = 0.35), then Linear → 128 logits (sigmoid only at
//!    inference).

use burn::module::Module;
use burn::nn::conv::{Conv3d, Conv3dConfig};
use burn::nn::pool::{MaxPool2d, MaxPool2dConfig};
use burn::nn::{
    BatchNorm, BatchNormConfig, Dropout, DropoutConfig, LayerNorm, LayerNormConfig, Linear, LinearConfig,
    PaddingConfig3d,
};
use burn::tensor::activation::leaky_relu;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::nbvnet::{max_pool3d_2, view_positions, CLASSES};
use crate::LearnError;

/// The LeakyReLU slope of every activation.
const SLOPE: f64 = 0.1;

/// The network's shape: grid, channel widths, FC widths, head dropout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MascvpShape {
    /// Input grid cells per axis G (a multiple of 16, ≥ 16).
    pub grid: usize,
    /// conv1's output channels C₀.
    pub conv1: usize,
    /// The three SCVP blocks' output channels C₁, C₂, C₃.
    pub blocks: [usize; 3],
    /// The hidden FC widths (each followed by LeakyReLU and dropout); the output layer to 128
    /// logits comes after them.
    pub fc: Vec<usize>,
    /// The head's dropout probability.
    pub dropout: f64,
}

impl MascvpShape {
    /// The reference shape: 64³, 32/64/128/256, FC 512/256/128/128, dropout 0.35.
    pub fn reference() -> MascvpShape {
        MascvpShape {
            grid: 64,
            conv1: 32,
            blocks: [64, 128, 256],
            fc: vec![512, 256, 128, 128],
            dropout: 0.35,
        }
    }

    /// The trained default: 32³ at quarter width (8/16/32/64), the reference's FC widths.
    pub fn scaled() -> MascvpShape {
        MascvpShape { grid: 32, conv1: 8, blocks: [16, 32, 64], fc: vec![512, 256, 128, 128], dropout: 0.35 }
    }

    /// Checks the sizes (an error names the setting).
    pub fn validate(&self) -> Result<(), LearnError> {
        let bad = |m: String| Err(LearnError::Invalid(m));
        if self.grid < 16 || !self.grid.is_multiple_of(16) || 64 % self.grid != 0 {
            return bad(format!("ma-scvp grid must be 16, 32 or 64, got {}", self.grid));
        }
        if self.conv1 == 0 || self.blocks.contains(&0) || self.fc.contains(&0) {
            return bad(format!(
                "ma-scvp widths must be positive: conv1 {}, blocks {:?}, fc {:?}",
                self.conv1, self.blocks, self.fc
            ));
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return bad(format!("ma-scvp dropout must be in [0, 1), got {}", self.dropout));
        }
        Ok(())
    }

    /// Channels after the dense skips (C₃ + C₂ + C₁ + C₀ + 4).
    pub fn skip_channels(&self) -> usize {
        self.blocks.iter().sum::<usize>() + self.conv1 + 4
    }

    /// Values of the BatchNorm running statistics (mean and variance of 8 norms per block),
    /// which Burn's `num_params` counts but the reference's parameter count does not.
    pub fn running_stats(&self) -> usize {
        2 * 8 * self.blocks.iter().sum::<usize>()
    }

    /// The trainable parameters of `net` of this shape (Burn's count minus
    /// [`MascvpShape::running_stats`]).
    pub fn trainable_params(&self, net: &MascvpNet) -> usize {
        net.num_params() - self.running_stats()
    }

    /// The flattened size entering the head.
    pub fn flat(&self) -> usize {
        self.skip_channels() * (self.grid / 16).pow(3)
    }

    /// How this shape differs from the reference (recorded in sidecars and results).
    pub fn deviation(&self) -> String {
        let r = MascvpShape::reference();
        if *self == r {
            return "none: the reference shape (64^3 input, 32/64/128/256, FC 512/256/128/128, 34,184,260 parameters)"
                .into();
        }
        format!(
            "scaled to fit a 2-core CPU: {g}^3 input (the 64^3 grid average-pooled by {p}), conv1 {c0} and \
             block widths {b:?} instead of 32 and [64, 128, 256], FC {fc:?} (reference [512, 256, 128, 128]) \
             from a flatten of {flat} instead of 30,976; same block topology, context MLP, skips and head",
            g = self.grid,
            p = 64 / self.grid,
            c0 = self.conv1,
            b = self.blocks,
            fc = self.fc,
            flat = self.flat()
        )
    }
}

/// Conv3d k3 p1 without bias, BatchNorm3d, LeakyReLU 0.1.
#[derive(Module, Debug)]
pub struct CnnBlock {
    conv: Conv3d,
    norm: BatchNorm,
}

impl CnnBlock {
    fn new(i: usize, o: usize, device: &Device) -> CnnBlock {
        CnnBlock {
            conv: Conv3dConfig::new([i, o], [3, 3, 3])
                .with_padding(PaddingConfig3d::Explicit(1, 1, 1))
                .with_bias(false)
                .init(device),
            norm: BatchNormConfig::new(o).init(device),
        }
    }
    fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        leaky_relu(self.norm.forward(self.conv.forward(x)), SLOPE)
    }
}

/// The SCVP residual block: two stacks of four [`CnnBlock`]s, LeakyReLU(stack2(s1) + s1).
#[derive(Module, Debug)]
pub struct ScvpBlock {
    stack1: Vec<CnnBlock>,
    stack2: Vec<CnnBlock>,
}

impl ScvpBlock {
    fn new(i: usize, o: usize, device: &Device) -> ScvpBlock {
        ScvpBlock {
            stack1: (0..4).map(|k| CnnBlock::new(if k == 0 { i } else { o }, o, device)).collect(),
            stack2: (0..4).map(|_| CnnBlock::new(o, o, device)).collect(),
        }
    }
    fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let s1 = self.stack1.iter().fold(x, |x, b| b.forward(x));
        let s2 = self.stack2.iter().fold(s1.clone(), |x, b| b.forward(x));
        leaky_relu(s2 + s1, SLOPE)
    }
}

/// The network (see the module docs).
#[derive(Module, Debug)]
pub struct MascvpNet {
    conv1: Conv3d,
    ctx1: Linear,
    ctx_norm1: LayerNorm,
    ctx_drop: Dropout,
    ctx2: Linear,
    ctx_norm2: LayerNorm,
    ctx3: Linear,
    block1: ScvpBlock,
    down1: Conv3d,
    block2: ScvpBlock,
    down2: Conv3d,
    block3: ScvpBlock,
    down3: Conv3d,
    fc: Vec<Linear>,
    head_drop: Dropout,
    out: Linear,
    pool: MaxPool2d,
    grid: usize,
}

impl MascvpNet {
    /// A freshly initialized network of `shape` on `device` (seed the device first for
    /// reproducible weights). The shape must be valid ([`MascvpShape::validate`]).
    pub fn new(shape: &MascvpShape, device: &Device) -> MascvpNet {
        shape.validate().expect("a valid MA-SCVP shape");
        let [c1, c2, c3] = shape.blocks;
        let c0 = shape.conv1;
        let down = |c| Conv3dConfig::new([c, c], [2, 2, 2]).with_stride([2, 2, 2]).init(device);
        let mut fc = Vec::new();
        let mut width = shape.flat();
        for &w in &shape.fc {
            fc.push(LinearConfig::new(width, w).init(device));
            width = w;
        }
        MascvpNet {
            conv1: Conv3dConfig::new([1, c0], [3, 3, 3])
                .with_padding(PaddingConfig3d::Explicit(1, 1, 1))
                .init(device),
            ctx1: LinearConfig::new(4, 64).init(device),
            ctx_norm1: LayerNormConfig::new(64).init(device),
            ctx_drop: DropoutConfig::new(0.1).init(),
            ctx2: LinearConfig::new(64, 64).init(device),
            ctx_norm2: LayerNormConfig::new(64).init(device),
            ctx3: LinearConfig::new(64, 4).init(device),
            block1: ScvpBlock::new(c0 + 4, c1, device),
            down1: down(c1),
            block2: ScvpBlock::new(c1, c2, device),
            down2: down(c2),
            block3: ScvpBlock::new(c2, c3, device),
            down3: down(c3),
            fc,
            head_drop: DropoutConfig::new(shape.dropout).init(),
            out: LinearConfig::new(width, CLASSES).init(device),
            pool: MaxPool2dConfig::new([2, 2]).init(),
            grid: shape.grid,
        }
    }

    /// The grid size G this network takes.
    pub fn grid(&self) -> usize {
        self.grid
    }

    /// Logits [B, 128] for grids [B, 1, G, G, G] (occupancy probabilities, C order) and view
    /// states [B, 128] (1.0 for a visited view, 0.0 otherwise).
    pub fn forward(&self, x: Tensor<5>, vs: Tensor<2>) -> Tensor<2> {
        let device = x.device();
        let [b, _, _, _, _] = x.dims();
        let h = self.grid / 2;
        let x1 = max_pool3d_2(&self.pool, self.conv1.forward(x));
        let pos = Tensor::<2>::from_data(TensorData::new(view_positions(), [CLASSES, 3]), &device);
        let tokens =
            Tensor::cat(vec![vs.reshape([b, CLASSES, 1]), pos.reshape([1, CLASSES, 3]).repeat_dim(0, b)], 2);
        let t = leaky_relu(self.ctx_norm1.forward(self.ctx1.forward(tokens)), SLOPE);
        let t = self.ctx_drop.forward(t);
        let t = leaky_relu(self.ctx_norm2.forward(self.ctx2.forward(t)), SLOPE);
        let t = self.ctx3.forward(t); // [B, 128, 4]
        let per_view = h * h * h / CLASSES;
        let ctx = t
            .swap_dims(1, 2) // [B, 4, 128]
            .reshape([b, 4, CLASSES, 1])
            .repeat_dim(3, per_view) // block v = token v
            .reshape([b, 4, h, h, h]);
        let x1 = Tensor::cat(vec![x1, ctx], 1);
        let x2 = self.down1.forward(self.block1.forward(x1.clone()));
        let x3 = self.down2.forward(self.block2.forward(x2.clone()));
        let x4 = self.down3.forward(self.block3.forward(x3.clone()));
        let x2 = Tensor::cat(vec![x2, max_pool3d_2(&self.pool, x1)], 1);
        let x3 = Tensor::cat(vec![x3, max_pool3d_2(&self.pool, x2)], 1);
        let x4 = Tensor::cat(vec![x4, max_pool3d_2(&self.pool, x3)], 1);
        let [b, c, d, hh, w] = x4.dims();
        let mut y = x4.reshape([b, c * d * hh * w]);
        for l in &self.fc {
            y = self.head_drop.forward(leaky_relu(l.forward(y), SLOPE));
        }
        self.out.forward(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_shape_forward_and_parameter_count() {
        let device = Device::flex();
        device.seed(1);
        let s = MascvpShape::scaled();
        let net = MascvpNet::new(&s, &device);
        assert_eq!(s.flat(), (64 + 32 + 16 + 8 + 4) * 8);
        let x = Tensor::<5>::full([2, 1, 32, 32, 32], 0.5, &device);
        let vs = Tensor::<2>::zeros([2, 128], &device);
        let out = net.forward(x, vs);
        assert_eq!(out.dims(), [2, 128]);
        let v: Vec<f32> = out.into_data().try_to_vec::<f32>().unwrap();
        assert!(v.iter().all(|x| x.is_finite()));
        // Hand count (learned-baselines.md §3.3's formula at quarter width, flatten 992):
        // conv1 8·27+8, context 320+128+4160+128+260, blocks Σ (in·out + 7·out²)·27 + 16·out,
        // downs c²·8 + c, FC 992·512+512 + 512·256+256 + 256·128+128 + 128·128+128 + 128·128+128.
        let blocks: usize = [(12usize, 16usize), (16, 32), (32, 64)]
            .iter()
            .map(|&(i, o)| (i * o + 7 * o * o) * 27 + 16 * o + o * o * 8 + o)
            .sum();
        let fc = 992 * 512 + 512 + 512 * 256 + 256 + 256 * 128 + 128 + 2 * (128 * 128 + 128);
        assert_eq!(s.trainable_params(&net), 8 * 27 + 8 + 4996 + blocks + fc);
        assert_eq!(net.num_params(), s.trainable_params(&net) + 2 * 8 * (16 + 32 + 64));
        assert!(s.deviation().contains("32^3"));
        assert!(MascvpShape::reference().deviation().starts_with("none"));
    }

    #[test]
    fn shapes_are_validated() {
        let mut s = MascvpShape::scaled();
        s.grid = 24;
        assert!(s.validate().unwrap_err().to_string().contains("24"));
        let mut s = MascvpShape::scaled();
        s.blocks[1] = 0;
        assert!(s.validate().is_err());
        let mut s = MascvpShape::scaled();
        s.dropout = 1.0;
        assert!(s.validate().is_err());
    }

    /// The view state reaches the logits (through the context MLP).
    #[test]
    fn view_state_changes_the_logits() {
        let device = Device::flex();
        device.seed(3);
        let s = MascvpShape { grid: 16, conv1: 2, blocks: [2, 2, 2], fc: vec![8], dropout: 0.35 };
        let net = MascvpNet::new(&s, &device);
        let x = Tensor::<5>::full([1, 1, 16, 16, 16], 0.5, &device);
        let a: Vec<f32> = net
            .forward(x.clone(), Tensor::<2>::zeros([1, 128], &device))
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let mut vs = vec![0.0f32; 128];
        vs[7] = 1.0;
        let vs = Tensor::<2>::from_data(TensorData::new(vs, [1, 128]), &device);
        let b: Vec<f32> = net.forward(x, vs).into_data().try_to_vec::<f32>().unwrap();
        assert_ne!(a, b);
    }

    /// The reference shape builds with exactly the reference's parameter count (34,184,260,
    /// learned-baselines.md §3.3) and runs one forward pass at 64³ (batch 1).
    #[test]
    fn reference_shape_forward_and_parameter_count() {
        let device = Device::flex();
        device.seed(2);
        let r = MascvpShape::reference();
        let net = MascvpNet::new(&r, &device);
        assert_eq!(r.flat(), 30_976);
        assert_eq!(r.trainable_params(&net), 34_184_260);
        let out = net.forward(
            Tensor::<5>::full([1, 1, 64, 64, 64], 0.5, &device),
            Tensor::<2>::zeros([1, 128], &device),
        );
        assert_eq!(out.dims(), [1, 128]);
    }
}
