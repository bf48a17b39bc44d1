//! Light sources for ray-traced corrections: a sun (directional), point lights and
//! rectangular area lights. The diffuse base image does not use them (its lighting is the
//! client's fixed shading); the correction tracer does.

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

#[cfg(test)]
mod tests {
    use super::*;

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
