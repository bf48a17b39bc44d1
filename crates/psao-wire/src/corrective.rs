//! The messages of corrective splatting (DESIGN §8, `docs/CORRECTIVE.md`): the client's
//! regions and their priorities, and the server's traced samples, with their validation rules.

use serde::{Deserialize, Serialize};

use crate::WireError;

/// Most regions one [`RegionsMsg`] may list (its largest encoding stays far below
/// [`crate::MAX_CLIENT_FRAME`]; tested).
pub const MAX_REGIONS: usize = 1024;
/// Largest image side a [`RegionsMsg`] may describe, pixels.
pub const MAX_REGION_IMAGE_SIDE: u32 = 16_384;
/// Most samples one [`SamplesMsg`] may carry.
pub const MAX_SAMPLES: usize = 65_536;
/// Highest √5 level a sample may have (a hierarchy over the largest image has fewer).
pub const MAX_SAMPLE_LEVEL: u8 = 32;
/// Largest radiance component a sample may carry (linear RGB; far above any light's).
pub const MAX_RADIANCE: f32 = 1.0e6;

/// One screen region (the bounding rectangle of a non-diffuse object's pixels inside one tile
/// of the image) and its priority.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Region {
    /// Object id (instance + 1; never 0).
    pub object: u32,
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// Column after the last.
    pub x1: u32,
    /// Row after the last.
    pub y1: u32,
    /// Priority in [0, 1] (saliency blended with task importance).
    pub priority: f32,
}

/// Client → server: the regions of a new analysis of the client's frame, for the camera of its
/// next `Camera` message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegionsMsg {
    /// Client frame the analysis was made on.
    pub frame: u32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// The regions; two regions of one object never overlap.
    pub regions: Vec<Region>,
}

/// One ray-traced correction sample.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SampleMsg {
    /// Object id (never 0).
    pub object: u32,
    /// √5 level (1 = coarsest).
    pub level: u8,
    /// World-space hit position of the primary ray.
    pub position: [f32; 3],
    /// Unit shading normal, facing the camera it was traced from.
    pub normal: [f32; 3],
    /// `normal · v` at creation (`v` towards the eye), in [−1, 1].
    pub ndotv: f32,
    /// Linear RGB radiance, each in [0, [`MAX_RADIANCE`]].
    pub color: [f32; 3],
}

/// Server → client: samples traced for the client's camera of camera age `camera_age`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplesMsg {
    /// Lockstep: the client frame whose camera they were traced for.
    pub client_frame: Option<u32>,
    /// Camera changes the server saw in this session before tracing them.
    pub camera_age: u32,
    /// The samples.
    pub samples: Vec<SampleMsg>,
}

fn invalid(text: String) -> WireError {
    WireError::Invalid(text)
}

impl RegionsMsg {
    /// Sizes, rectangles inside the image, priorities in [0, 1], no two regions of one object
    /// overlapping.
    pub(crate) fn validate(&self) -> Result<(), WireError> {
        let side = 1..=MAX_REGION_IMAGE_SIDE;
        if !side.contains(&self.width) || !side.contains(&self.height) {
            return Err(invalid(format!(
                "regions: image {}×{} outside 1..={MAX_REGION_IMAGE_SIDE}",
                self.width, self.height
            )));
        }
        if self.regions.len() > MAX_REGIONS {
            return Err(invalid(format!(
                "{} regions exceed {MAX_REGIONS}",
                self.regions.len()
            )));
        }
        for r in &self.regions {
            if r.object == 0 {
                return Err(invalid("region of object 0 (diffuse)".into()));
            }
            let inside = r.x0 < r.x1 && r.y0 < r.y1 && r.x1 <= self.width && r.y1 <= self.height;
            if !inside {
                return Err(invalid(format!(
                    "region of object {}: rectangle [{}, {}) × [{}, {}) empty or outside the {}×{} image",
                    r.object, r.x0, r.x1, r.y0, r.y1, self.width, self.height
                )));
            }
            if !(0.0..=1.0).contains(&r.priority) {
                return Err(invalid(format!(
                    "region of object {}: priority {} outside [0, 1]",
                    r.object, r.priority
                )));
            }
        }
        let mut order: Vec<&Region> = self.regions.iter().collect();
        order.sort_unstable_by_key(|r| (r.object, r.x0));
        for (i, a) in order.iter().enumerate() {
            // Regions of a's object starting left of a's right edge (sorted by x0).
            let overlap = order[i + 1..]
                .iter()
                .take_while(|b| b.object == a.object && b.x0 < a.x1)
                .find(|b| b.y0 < a.y1 && a.y0 < b.y1);
            if let Some(b) = overlap {
                return Err(invalid(format!(
                    "object {} has overlapping regions [{}, {}) × [{}, {}) and [{}, {}) × [{}, {})",
                    a.object, a.x0, a.x1, a.y0, a.y1, b.x0, b.x1, b.y0, b.y1
                )));
            }
        }
        Ok(())
    }
}

impl SampleMsg {
    fn validate(&self) -> Result<(), WireError> {
        if self.object == 0 {
            return Err(invalid("sample of object 0 (diffuse)".into()));
        }
        if self.level == 0 || self.level > MAX_SAMPLE_LEVEL {
            return Err(invalid(format!(
                "sample level {} outside 1..={MAX_SAMPLE_LEVEL}",
                self.level
            )));
        }
        let finite = self
            .position
            .iter()
            .chain(&self.normal)
            .chain(&self.color)
            .chain([&self.ndotv])
            .all(|v| v.is_finite());
        if !finite {
            return Err(invalid("sample with a non-finite number".into()));
        }
        let len2: f32 = self.normal.iter().map(|v| v * v).sum();
        if (len2 - 1.0).abs() > 1e-3 {
            return Err(invalid(format!(
                "sample normal of length {} (must be unit)",
                len2.sqrt()
            )));
        }
        if self.ndotv.abs() > 1.0 + 1e-3 {
            return Err(invalid(format!(
                "sample n·v {} outside [−1, 1]",
                self.ndotv
            )));
        }
        if self.color.iter().any(|c| !(0.0..=MAX_RADIANCE).contains(c)) {
            return Err(invalid(format!(
                "sample colour {:?} outside [0, {MAX_RADIANCE}]",
                self.color
            )));
        }
        Ok(())
    }
}

impl SamplesMsg {
    /// At most [`MAX_SAMPLES`] samples, each valid.
    pub(crate) fn validate(&self) -> Result<(), WireError> {
        if self.samples.len() > MAX_SAMPLES {
            return Err(invalid(format!(
                "{} samples exceed {MAX_SAMPLES}",
                self.samples.len()
            )));
        }
        self.samples.iter().try_for_each(SampleMsg::validate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{decode_frame, encode_frame, frame_payload, Message, MAX_CLIENT_FRAME};

    fn regions(n: usize) -> RegionsMsg {
        RegionsMsg {
            frame: 7,
            width: MAX_REGION_IMAGE_SIDE,
            height: MAX_REGION_IMAGE_SIDE,
            regions: (0..n as u32)
                .map(|i| Region {
                    object: u32::MAX - i,
                    x0: MAX_REGION_IMAGE_SIDE - 2,
                    y0: 0,
                    x1: MAX_REGION_IMAGE_SIDE,
                    y1: MAX_REGION_IMAGE_SIDE,
                    priority: 0.5,
                })
                .collect(),
        }
    }

    fn sample() -> SampleMsg {
        SampleMsg {
            object: 3,
            level: 2,
            position: [1.0, 2.0, 3.0],
            normal: [0.0, 1.0, 0.0],
            ndotv: 0.7,
            color: [0.2, 0.4, 1.5],
        }
    }

    #[test]
    fn the_largest_regions_message_fits_a_client_frame_and_round_trips() {
        let m = Message::Regions(regions(MAX_REGIONS));
        let bytes = encode_frame(&m).unwrap();
        assert!(
            bytes.len() < MAX_CLIENT_FRAME as usize / 2,
            "{}",
            bytes.len()
        );
        assert_eq!(decode_frame(&bytes, MAX_CLIENT_FRAME).unwrap(), m);
        assert!(encode_frame(&Message::Regions(regions(MAX_REGIONS + 1))).is_err());
    }

    #[test]
    fn the_largest_samples_message_round_trips() {
        let m = Message::Samples(SamplesMsg {
            client_frame: Some(4),
            camera_age: 9,
            samples: vec![sample(); MAX_SAMPLES],
        });
        let bytes = encode_frame(&m).unwrap();
        assert_eq!(decode_frame(&bytes, crate::MAX_SERVER_FRAME).unwrap(), m);
    }

    /// Frames with a valid checksum whose message breaks a rule are refused on decoding.
    #[test]
    fn malformed_corrective_messages_are_refused() {
        let bad_regions = |f: &dyn Fn(&mut RegionsMsg)| {
            let mut m = regions(2);
            f(&mut m);
            let payload = postcard::to_stdvec(&Message::Regions(m)).unwrap();
            decode_frame(&frame_payload(&payload).unwrap(), MAX_CLIENT_FRAME)
        };
        let cases: [&dyn Fn(&mut RegionsMsg); 8] = [
            &|m| m.width = 0,
            &|m| m.height = MAX_REGION_IMAGE_SIDE + 1,
            &|m| m.regions[0].object = 0,
            &|m| m.regions[0].x1 = m.regions[0].x0,
            &|m| m.regions[0].y1 = MAX_REGION_IMAGE_SIDE + 1,
            &|m| m.regions[0].priority = f32::NAN,
            &|m| m.regions[0].priority = 1.5,
            &|m| m.regions[1].object = m.regions[0].object,
        ];
        for case in cases {
            assert!(matches!(bad_regions(case), Err(WireError::Invalid(_))));
        }
        // One object in two tiles: side by side is fine, one pixel of overlap is not.
        let side_by_side = |m: &mut RegionsMsg| {
            m.regions[1].object = m.regions[0].object;
            m.regions[1].x0 -= 2;
            m.regions[1].x1 -= 2;
        };
        assert!(bad_regions(&side_by_side).is_ok());
        assert!(matches!(
            bad_regions(&|m| {
                side_by_side(m);
                m.regions[1].x1 += 1;
            }),
            Err(WireError::Invalid(_))
        ));
        let bad_samples = |f: &dyn Fn(&mut SampleMsg)| {
            let mut s = sample();
            f(&mut s);
            let m = Message::Samples(SamplesMsg {
                client_frame: None,
                camera_age: 0,
                samples: vec![sample(), s],
            });
            let payload = postcard::to_stdvec(&m).unwrap();
            decode_frame(&frame_payload(&payload).unwrap(), MAX_CLIENT_FRAME)
        };
        let cases: [&dyn Fn(&mut SampleMsg); 8] = [
            &|s| s.object = 0,
            &|s| s.level = 0,
            &|s| s.level = MAX_SAMPLE_LEVEL + 1,
            &|s| s.position[2] = f32::INFINITY,
            &|s| s.normal = [0.0, 2.0, 0.0],
            &|s| s.ndotv = -1.5,
            &|s| s.color[1] = -0.1,
            &|s| s.color[0] = f32::NAN,
        ];
        for case in cases {
            assert!(matches!(bad_samples(case), Err(WireError::Invalid(_))));
        }
        // Too many samples, and a count prefix far above what the frame holds.
        let many = Message::Samples(SamplesMsg {
            client_frame: None,
            camera_age: 0,
            samples: vec![sample(); MAX_SAMPLES + 1],
        });
        let payload = postcard::to_stdvec(&many).unwrap();
        assert!(matches!(
            decode_frame(&frame_payload(&payload).unwrap(), u32::MAX),
            Err(WireError::Invalid(_))
        ));
        let mut lying = postcard::to_stdvec(&Message::Samples(SamplesMsg {
            client_frame: None,
            camera_age: 0,
            samples: vec![sample()],
        }))
        .unwrap();
        // Variant 10, no client frame, age 0, then the sample count: claim 2^28 samples.
        assert_eq!(&lying[..4], &[10, 0, 0, 1]);
        lying.splice(3..4, [0x80, 0x80, 0x80, 0x80, 0x01]);
        assert!(matches!(
            decode_frame(&frame_payload(&lying).unwrap(), MAX_CLIENT_FRAME),
            Err(WireError::Malformed(_))
        ));
        // Cut short.
        let whole = encode_frame(&Message::Regions(regions(3))).unwrap();
        let payload = &whole[crate::HEADER_LEN..whole.len() - 5];
        assert!(matches!(
            decode_frame(&frame_payload(payload).unwrap(), MAX_CLIENT_FRAME),
            Err(WireError::Malformed(_))
        ));
    }
}
