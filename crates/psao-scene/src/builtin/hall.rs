//! The architecture of the default scene: floor tiles, walls, columns, arcades, ceiling beams,
//! the stepped dais with its railings and the iron grille.

use glam::{Affine3A, Quat, Vec2, Vec3};

use super::shapes::{append, arc_profile, arcade, cuboid, cylinder, lathe, stairs};
use super::{at, at_yaw, Palette, SceneBuilder};
use crate::light::{Light, LightShape};
use crate::model::Mesh;

/// Inner half extents of the hall along x and z.
const HALF_X: f32 = 10.0;
const HALF_Z: f32 = 6.0;
/// Ceiling height (underside of the ceiling slab).
const CEILING: f32 = 6.0;
/// Wall thickness.
const WALL: f32 = 0.4;
/// z of the two column rows (±).
pub(super) const ROW_Z: f32 = 3.0;
/// Top of the column capitals, where the arches spring.
const COLUMN_TOP: f32 = 4.0;
/// Column x positions.
const COLUMN_X: [f32; 9] = [-8.0, -6.0, -4.0, -2.0, 0.0, 2.0, 4.0, 6.0, 8.0];
/// Ceiling beam x positions (the pendulum hangs from the one at x = 3).
const BEAM_X: [f32; 10] = [-9.0, -7.0, -5.0, -3.0, -1.0, 1.0, 3.0, 5.0, 7.0, 9.0];
/// Underside of the ceiling beams.
pub(super) const BEAM_BOTTOM: f32 = 5.6;
/// The dais: its stairs start at this x and it spans |z| ≤ DAIS_HALF_Z up to the east wall.
pub(super) const DAIS_X: f32 = 6.82;
pub(super) const DAIS_HALF_Z: f32 = 2.5;
/// Height of the dais top.
pub(super) const DAIS_TOP: f32 = 0.6;
const STEP_RUN: f32 = 0.32;
const STEPS: u32 = 4;

/// x of the centres of the ceiling's light panels (in the bays between beams).
const PANEL_X: [f32; 3] = [-6.0, 0.0, 6.0];
/// Edge lengths of a light panel along x and z.
const PANEL_SIZE: [f32; 2] = [1.5, 5.0];
/// Radiance of a light panel.
const PANEL_RADIANCE: f32 = 6.0;

/// The hall's lights: warm-white panels just under the ceiling over the nave, emitting down
/// (the hall is closed, so the sun and the sky light only its outside).
pub(super) fn lights() -> Vec<Light> {
    PANEL_X
        .iter()
        .map(|&x| Light {
            shape: LightShape::Rect {
                centre: Vec3::new(x, CEILING - 0.01, 0.0),
                // half_u × half_v points down: the side the panel emits to.
                half_u: Vec3::new(0.5 * PANEL_SIZE[0], 0.0, 0.0),
                half_v: Vec3::new(0.0, 0.0, 0.5 * PANEL_SIZE[1]),
            },
            color: Vec3::new(1.0, 0.93, 0.82),
            power: PANEL_RADIANCE,
        })
        .collect()
}

/// Builds all static architecture.
pub(super) fn build(b: &mut SceneBuilder, p: &Palette) {
    floor(b, p);
    walls(b, p);
    colonnades(b, p);
    ceiling(b, p);
    dais(b, p);
    grille(b, p);
}

/// Adds a box mesh spanning `min`..`max` and places it once.
pub(super) fn block(b: &mut SceneBuilder, name: &str, material: usize, min: Vec3, max: Vec3) {
    let mesh = b.mesh(cuboid((max - min) * 0.5), name, material);
    b.place(mesh, Affine3A::from_translation((min + max) * 0.5));
}

fn floor(b: &mut SceneBuilder, p: &Palette) {
    const TILE: f32 = 0.5;
    const GAP: f32 = 0.02;
    const DEPTH: f32 = 0.02;
    block(
        b,
        "floor_slab",
        p.marble_dark,
        Vec3::new(-HALF_X - WALL, -0.32, -HALF_Z - WALL),
        Vec3::new(HALF_X + WALL, -DEPTH, HALF_Z + WALL),
    );
    let half = Vec3::new(TILE * 0.5 - GAP * 0.5, DEPTH * 0.5, TILE * 0.5 - GAP * 0.5);
    let light = b.mesh(cuboid(half), "floor_tile_light", p.marble_light);
    let dark = b.mesh(cuboid(half), "floor_tile_dark", p.marble_dark);
    let (nx, nz) = ((2.0 * HALF_X / TILE) as i32, (2.0 * HALF_Z / TILE) as i32);
    for i in 0..nx {
        for j in 0..nz {
            let x = -HALF_X + (i as f32 + 0.5) * TILE;
            let z = -HALF_Z + (j as f32 + 0.5) * TILE;
            let under_dais = x - TILE * 0.5 >= DAIS_X && z.abs() + TILE * 0.5 <= DAIS_HALF_Z;
            if under_dais {
                continue;
            }
            let mesh = if (i + j) % 2 == 0 { light } else { dark };
            b.place(mesh, at(x, -DEPTH * 0.5, z));
        }
    }
}

fn walls(b: &mut SceneBuilder, p: &Palette) {
    let (x, z, w) = (HALF_X, HALF_Z, WALL);
    let (y0, y1) = (-0.02, CEILING);
    let v = Vec3::new;
    block(
        b,
        "wall_north",
        p.plaster,
        v(-x - w, y0, -z - w),
        v(x + w, y1, -z),
    );
    block(
        b,
        "wall_south",
        p.plaster,
        v(-x - w, y0, z),
        v(x + w, y1, z + w),
    );
    block(b, "wall_west", p.plaster, v(-x - w, y0, -z), v(-x, y1, z));
    block(b, "wall_east", p.plaster, v(x, y0, -z), v(x + w, y1, z));
    // Skirting boards along the foot of every wall.
    let (h, t) = (0.15, 0.03);
    block(
        b,
        "skirting_north",
        p.wood_dark,
        v(-x, 0.0, -z),
        v(x, h, -z + t),
    );
    block(
        b,
        "skirting_south",
        p.wood_dark,
        v(-x, 0.0, z - t),
        v(x, h, z),
    );
    block(
        b,
        "skirting_west",
        p.wood_dark,
        v(-x, 0.0, -z + t),
        v(-x + t, h, z - t),
    );
    block(
        b,
        "skirting_east",
        p.wood_dark,
        v(x - t, 0.0, -z + t),
        v(x, h, z - t),
    );
    // Pilasters facing the columns: local +z points into the hall.
    let pilaster = pilaster_mesh();
    let pilaster = b.mesh(pilaster, "pilaster", p.stone);
    for &cx in &COLUMN_X {
        b.place(pilaster, at_yaw(cx, 0.0, -z, 0.0));
        b.place(pilaster, at_yaw(cx, 0.0, z, 180.0));
    }
    for sz in [-ROW_Z, ROW_Z] {
        b.place(pilaster, at_yaw(-x, 0.0, sz, 90.0));
        b.place(pilaster, at_yaw(x, 0.0, sz, -90.0));
    }
}

/// A flat pilaster with base and capital blocks, its back on the plane z = 0.
fn pilaster_mesh() -> Mesh {
    let mut m = Mesh::default();
    append(
        &mut m,
        &cuboid(Vec3::new(0.25, 2.8, 0.06)),
        at(0.0, 2.8, 0.06),
    );
    append(
        &mut m,
        &cuboid(Vec3::new(0.31, 0.1, 0.1)),
        at(0.0, 0.1, 0.1),
    );
    append(
        &mut m,
        &cuboid(Vec3::new(0.31, 0.08, 0.1)),
        at(0.0, 5.52, 0.1),
    );
    m
}

/// The column: square plinth, turned base with two tori, tapering shaft, astragal, echinus and
/// a square abacus; 48 segments around.
fn column_mesh() -> Mesh {
    let v = Vec2::new;
    let mut profile = vec![v(0.0, 0.2), v(0.30, 0.2)];
    profile.extend(
        arc_profile(
            v(0.30, 0.265),
            0.065,
            -90f32.to_radians(),
            90f32.to_radians(),
            10,
        )
        .into_iter()
        .skip(1),
    );
    profile.extend([v(0.27, 0.33), v(0.27, 0.36)]);
    profile.extend(
        arc_profile(
            v(0.27, 0.39),
            0.03,
            -90f32.to_radians(),
            90f32.to_radians(),
            8,
        )
        .into_iter()
        .skip(1),
    );
    // Shaft with a slight entasis from r = 0.25 to 0.22.
    for k in 0..=8 {
        let t = k as f32 / 8.0;
        profile.push(v(0.25 - 0.03 * t.powf(1.5), 0.42 + 3.08 * t));
    }
    profile.extend(
        arc_profile(
            v(0.22, 3.53),
            0.03,
            -90f32.to_radians(),
            90f32.to_radians(),
            8,
        )
        .into_iter()
        .skip(1),
    );
    profile.push(v(0.22, 3.62));
    // Echinus: a quarter ellipse flaring out to the abacus.
    for k in 1..=8 {
        let a = (k as f32 / 8.0) * std::f32::consts::FRAC_PI_2;
        profile.push(v(0.22 + 0.14 * a.sin(), 3.80 - 0.18 * a.cos()));
    }
    profile.extend([v(0.36, 3.85), v(0.0, 3.85)]);
    let mut m = lathe(&profile, 48, 40.0);
    append(
        &mut m,
        &cuboid(Vec3::new(0.38, 0.1, 0.38)),
        at(0.0, 0.1, 0.0),
    );
    append(
        &mut m,
        &cuboid(Vec3::new(0.4, 0.075, 0.4)),
        at(0.0, COLUMN_TOP - 0.075, 0.0),
    );
    m
}

fn colonnades(b: &mut SceneBuilder, p: &Palette) {
    let column = b.mesh(column_mesh(), "column", p.stone);
    let arches = b.mesh(arcade(8, 1.0, 0.6, 1.2, 0.5, 48), "arcade", p.stone);
    let beam = b.mesh(cuboid(Vec3::new(HALF_X, 0.2, 0.3)), "entablature", p.stone);
    for z in [-ROW_Z, ROW_Z] {
        for &x in &COLUMN_X {
            b.place(column, at(x, 0.0, z));
        }
        b.place(arches, at(0.0, COLUMN_TOP, z));
        b.place(beam, at(0.0, COLUMN_TOP + 1.4, z));
    }
}

fn ceiling(b: &mut SceneBuilder, p: &Palette) {
    block(
        b,
        "ceiling",
        p.plaster,
        Vec3::new(-HALF_X - WALL, CEILING, -HALF_Z - WALL),
        Vec3::new(HALF_X + WALL, CEILING + 0.3, HALF_Z + WALL),
    );
    let half_h = (CEILING - BEAM_BOTTOM) * 0.5;
    let beam = b.mesh(
        cuboid(Vec3::new(0.125, half_h, HALF_Z)),
        "ceiling_beam",
        p.wood_dark,
    );
    let corbel = b.mesh(cuboid(Vec3::new(0.1, 0.12, 0.15)), "corbel", p.wood_dark);
    for &x in &BEAM_X {
        b.place(beam, at(x, BEAM_BOTTOM + half_h, 0.0));
        for z in [-HALF_Z + 0.15, HALF_Z - 0.15] {
            b.place(corbel, at(x, BEAM_BOTTOM - 0.12, z));
        }
    }
}

/// The stepped dais at the east end, with railings along its two sides.
fn dais(b: &mut SceneBuilder, p: &Palette) {
    let rise = DAIS_TOP / STEPS as f32;
    let landing = HALF_X - DAIS_X - (STEPS - 1) as f32 * STEP_RUN;
    let flight = stairs(2.0 * DAIS_HALF_Z, rise, STEP_RUN, STEPS, landing);
    let flight = b.mesh(flight, "dais_stairs", p.stone);
    // Local +z (ascending) becomes world +x.
    b.place(
        flight,
        Affine3A::from_rotation_translation(
            Quat::from_rotation_y(90f32.to_radians()),
            Vec3::new(DAIS_X, 0.0, 0.0),
        ),
    );
    let x0 = DAIS_X + (STEPS - 1) as f32 * STEP_RUN + 0.12;
    let rail = railing_mesh(HALF_X - 0.1 - x0, 0.9);
    let rail = b.mesh(rail, "dais_railing", p.polished_iron);
    for z in [-DAIS_HALF_Z + 0.06, DAIS_HALF_Z - 0.06] {
        b.place(rail, at(x0, DAIS_TOP, z));
    }
}

/// A railing running along +x from x = 0 to `length`: thin round balusters every 12 cm between
/// square end posts, a bottom rail and a hand rail.
fn railing_mesh(length: f32, height: f32) -> Mesh {
    let mut m = Mesh::default();
    let post = cuboid(Vec3::new(0.04, height * 0.5 + 0.03, 0.04));
    append(&mut m, &post, at(0.0, height * 0.5 + 0.03, 0.0));
    append(&mut m, &post, at(length, height * 0.5 + 0.03, 0.0));
    let rail = cuboid(Vec3::new(length * 0.5, 0.02, 0.03));
    append(&mut m, &rail, at(length * 0.5, height, 0.0));
    append(&mut m, &rail, at(length * 0.5, 0.08, 0.0));
    let bars = ((length - 0.08) / 0.12).floor() as i32;
    let step = length / (bars + 1) as f32;
    let baluster = cylinder(0.012, height, 12);
    for k in 1..=bars {
        append(&mut m, &baluster, at(k as f32 * step, 0.0, 0.0));
    }
    m
}

/// An iron grille screen standing 0.35 m in front of the west wall.
fn grille(b: &mut SceneBuilder, p: &Palette) {
    let (half_len, height) = (1.5, 2.4);
    let mut m = Mesh::default();
    let post = cuboid(Vec3::new(0.03, height * 0.5 + 0.05, 0.03));
    for z in [-half_len, half_len] {
        append(&mut m, &post, at(0.0, height * 0.5 + 0.05, z));
    }
    let bar = cuboid(Vec3::new(0.01, 0.025, half_len));
    for y in [0.1, 1.2, height] {
        append(&mut m, &bar, at(0.0, y, 0.0));
    }
    let rod = cylinder(0.012, height, 12);
    let count = 29;
    for k in 1..=count {
        let z = -half_len + 2.0 * half_len * k as f32 / (count + 1) as f32;
        append(&mut m, &rod, at(0.0, 0.0, z));
    }
    let grille = b.mesh(m, "grille", p.iron);
    b.place(grille, at(-HALF_X + 0.35, 0.0, 0.0));
}
