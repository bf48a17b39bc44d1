//! A single-channel image of AO values in [0, 1].

use serde::{Deserialize, Serialize};

/// A row-major grayscale image with values in [0, 1] (1 = unoccluded).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AoImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` values, row-major from the top-left pixel.
    pub data: Vec<f32>,
}

impl AoImage {
    /// An image filled with `value`.
    pub fn filled(width: u32, height: u32, value: f32) -> Self {
        Self {
            width,
            height,
            data: vec![value; width as usize * height as usize],
        }
    }

    /// Values quantised to 16 bits (for lossless-enough PNG storage).
    pub fn to_u16(&self) -> Vec<u16> {
        self.data
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
            .collect()
    }

    /// Values quantised to 8 bits, as they would be displayed.
    pub fn to_u8(&self) -> Vec<u8> {
        self.data
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect()
    }

    /// Builds an image from 16-bit samples.
    pub fn from_u16(width: u32, height: u32, samples: &[u16]) -> Self {
        Self {
            width,
            height,
            data: samples.iter().map(|&s| s as f32 / 65535.0).collect(),
        }
    }

    /// Mean value over all pixels (1 for an empty image).
    pub fn mean(&self) -> f32 {
        if self.data.is_empty() {
            return 1.0;
        }
        (self.data.iter().map(|&v| v as f64).sum::<f64>() / self.data.len() as f64) as f32
    }
}
