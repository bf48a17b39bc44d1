//! Light sources: a sun (directional, its direction optionally following keys over time),
//! point lights and rectangular area lights. The correction tracer and the diffuse lighting
//! (`psao_trace::light`) use them.

use glam::Vec3;

/// Where a light is and what shape it has.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightShape {
    /// A directional light; `direction` points from the surface towards the light.
    Sun {
        /// Unit direction towards the light.
        direction: Vec3,
    },
    /// A point light.
    Point {
        /// World position.
        position: Vec3,
    },
    /// A one-sided rectangle emitting towards `edge_u × edge_v`.
    Rect {
        /// World position of the centre.
        centre: Vec3,
        /// Half of one edge, as a world vector.
        half_u: Vec3,
        /// Half of the other edge, as a world vector.
        half_v: Vec3,
    },
}

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Shape and placement.
    pub shape: LightShape,
    /// Linear RGB colour (components in [0, 1]).
    pub color: Vec3,
    /// Strength: for a sun the irradiance on a surface facing it, for a point light the
    /// radiant intensity (irradiance `power / d²` at distance `d`), for a rectangle its
    /// radiance. Never negative.
    pub power: f32,
}

impl Light {
    /// Checks the light: finite values, colour in [0, 1], non-negative power, a non-zero sun
    /// direction and a rectangle of non-zero area; the message names the problem.
    pub fn check(&self) -> Result<(), String> {
        if !(self.power.is_finite() && self.power >= 0.0) {
            return Err(format!(
                "light power must be a non-negative number, got {}",
                self.power
            ));
        }
        if !self.color.is_finite()
            || self.color.min_element() < 0.0
            || self.color.max_element() > 1.0
        {
            return Err(format!(
                "light colour must be in [0, 1], got {}",
                self.color
            ));
        }
        match self.shape {
            LightShape::Sun { direction } => {
                if !direction.is_finite() || direction.length_squared() < 1e-12 {
                    return Err(format!("sun direction must be non-zero, got {direction}"));
                }
            }
            LightShape::Point { position } => {
                if !position.is_finite() {
                    return Err("point light position is not finite".into());
                }
            }
            LightShape::Rect {
                centre,
                half_u,
                half_v,
            } => {
                if !(centre.is_finite() && half_u.is_finite() && half_v.is_finite()) {
                    return Err("rectangle light has non-finite values".into());
                }
                if half_u.cross(half_v).length_squared() < 1e-12 {
                    return Err("rectangle light has zero area".into());
                }
            }
        }
        Ok(())
    }

    /// The light moved by `f` (positions by the transform, directions by its linear part).
    pub fn transformed(&self, f: &glam::Affine3A) -> Light {
        let shape = match self.shape {
            LightShape::Sun { direction } => LightShape::Sun {
                direction: f.transform_vector3(direction).normalize_or(direction),
            },
            LightShape::Point { position } => LightShape::Point {
                position: f.transform_point3(position),
            },
            LightShape::Rect {
                centre,
                half_u,
                half_v,
            } => LightShape::Rect {
                centre: f.transform_point3(centre),
                half_u: f.transform_vector3(half_u),
                half_v: f.transform_vector3(half_v),
            },
        };
        Light { shape, ..*self }
    }
}

/// A sun whose direction follows keys over time (a scene-file sun's `keys`): spherical
/// linear interpolation between consecutive keys, looping over the last key time (held
/// before the first).
#[derive(Clone, Debug, PartialEq)]
pub struct SunKeys {
    /// Index into `Scene::lights` of the sun it turns.
    pub light: usize,
    /// Key times in seconds, non-decreasing, finite.
    pub times: Vec<f32>,
    /// Unit direction towards the sun at each key; consecutive keys not opposite.
    pub directions: Vec<Vec3>,
}

impl SunKeys {
    /// Checks the keys: as many finite, non-decreasing times as non-zero directions, no two
    /// consecutive directions opposite (the way between them would be undefined).
    pub fn new(light: usize, times: Vec<f32>, directions: Vec<Vec3>) -> Result<Self, String> {
        if times.is_empty() || times.iter().any(|t| !t.is_finite()) {
            return Err("keys: times must be a non-empty list of finite seconds".into());
        }
        if times.windows(2).any(|w| w[1] < w[0]) {
            return Err("keys: times must not decrease".into());
        }
        if times.len() != directions.len() {
            return Err(format!(
                "keys: {} directions for {} times",
                directions.len(),
                times.len()
            ));
        }
        let mut unit = Vec::with_capacity(directions.len());
        for (k, d) in directions.iter().enumerate() {
            if !d.is_finite() || d.length_squared() < 1e-12 {
                return Err(format!("keys: direction {k} must be non-zero, got {d}"));
            }
            unit.push(d.normalize());
        }
        if let Some(k) = unit.windows(2).position(|w| w[0].dot(w[1]) < -0.9999) {
            return Err(format!(
                "keys: directions {k} and {} are opposite (the sun's way between them is undefined)",
                k + 1
            ));
        }
        Ok(Self {
            light,
            times,
            directions: unit,
        })
    }

    /// The unit direction towards the sun at scene time `t` seconds.
    pub fn direction_at(&self, t: f32) -> Vec3 {
        let last = *self.times.last().expect("keys are not empty");
        let t = if last > 0.0 && t.is_finite() {
            t.rem_euclid(last)
        } else {
            t
        };
        let k = self.times.partition_point(|&k| k <= t);
        if k == 0 {
            return self.directions[0];
        }
        if k == self.times.len() {
            return self.directions[k - 1];
        }
        let (t0, t1) = (self.times[k - 1], self.times[k]);
        let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
        slerp(self.directions[k - 1], self.directions[k], s)
    }
}

/// Spherical linear interpolation of two unit vectors that are not opposite.
fn slerp(a: Vec3, b: Vec3, s: f32) -> Vec3 {
    let q = glam::Quat::from_rotation_arc(a, b);
    (glam::Quat::IDENTITY.slerp(q, s) * a).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sun_keys_interpolate_on_the_sphere_and_loop() {
        let keys = SunKeys::new(
            0,
            vec![0.0, 10.0, 20.0],
            vec![Vec3::X, Vec3::Y * 3.0, Vec3::NEG_X],
        )
        .unwrap();
        assert!((keys.direction_at(0.0) - Vec3::X).length() < 1e-6);
        assert!((keys.direction_at(10.0) - Vec3::Y).length() < 1e-6);
        let half = Vec3::new(1.0, 1.0, 0.0).normalize();
        assert!((keys.direction_at(5.0) - half).length() < 1e-5);
        // Looping over the last key time: 25 s is 5 s.
        assert!((keys.direction_at(25.0) - half).length() < 1e-5);
        assert!((keys.direction_at(-15.0) - half).length() < 1e-5);
        assert!((keys.direction_at(15.0) - (Vec3::NEG_X + Vec3::Y).normalize()).length() < 1e-5);
        let err = SunKeys::new(0, vec![0.0, 1.0], vec![Vec3::X, Vec3::NEG_X]).unwrap_err();
        assert!(err.contains("opposite"), "{err}");
        assert!(SunKeys::new(0, vec![1.0, 0.0], vec![Vec3::X, Vec3::Y])
            .unwrap_err()
            .contains("decrease"));
        assert!(SunKeys::new(0, vec![0.0], vec![Vec3::X, Vec3::Y])
            .unwrap_err()
            .contains("2 directions for 1 times"));
        assert!(SunKeys::new(0, vec![0.0], vec![Vec3::ZERO])
            .unwrap_err()
            .contains("non-zero"));
    }

    fn sun(power: f32) -> Light {
        Light {
            shape: LightShape::Sun { direction: Vec3::Y },
            color: Vec3::ONE,
            power,
        }
    }

    #[test]
    fn bad_lights_are_named() {
        assert!(sun(1.0).check().is_ok());
        assert!(sun(-1.0).check().unwrap_err().contains("non-negative"));
        assert!(sun(f32::NAN).check().is_err());
        let mut l = sun(1.0);
        l.color = Vec3::new(1.5, 0.0, 0.0);
        assert!(l.check().unwrap_err().contains("colour"));
        l = sun(1.0);
        l.shape = LightShape::Sun {
            direction: Vec3::ZERO,
        };
        assert!(l.check().unwrap_err().contains("direction"));
        l.shape = LightShape::Rect {
            centre: Vec3::ZERO,
            half_u: Vec3::X,
            half_v: Vec3::X * 2.0,
        };
        assert!(l.check().unwrap_err().contains("zero area"));
    }
}
