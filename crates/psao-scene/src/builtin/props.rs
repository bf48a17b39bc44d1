//! Static furniture and small objects of the default scene: benches, crates, barrels, vases,
//! a table with things on it, stools and pedestals.

use glam::{Vec2, Vec3};

use super::hall::{DAIS_HALF_Z, DAIS_TOP, DAIS_X, ROW_Z};
use super::shapes::{append, cuboid, cylinder, lathe, sphere};
use super::{at, at_yaw, Palette, SceneBuilder};
use crate::model::Mesh;

/// Table centre (x, z) and top height; the sliding box moves on it.
pub(super) const TABLE_X: f32 = -3.0;
pub(super) const TABLE_TOP: f32 = 0.76;

/// Builds all static props.
pub(super) fn build(b: &mut SceneBuilder, p: &Palette) {
    benches(b, p);
    crates(b, p);
    barrels(b, p);
    vases(b, p);
    table(b, p);
    dais_ornaments(b, p);
}

fn benches(b: &mut SceneBuilder, p: &Palette) {
    let bench = b.mesh(bench_mesh(), "bench", p.wood);
    for x in [-7.0, -3.0, 1.0, 5.0] {
        b.place(bench, at_yaw(x, 0.0, -5.75, 0.0));
    }
    for x in [-3.0, 5.0] {
        b.place(bench, at_yaw(x, 0.0, 5.75, 180.0));
    }
}

/// A 1.4 m bench: seat plank on two slab legs joined by a stretcher.
fn bench_mesh() -> Mesh {
    let mut m = Mesh::default();
    append(
        &mut m,
        &cuboid(Vec3::new(0.7, 0.03, 0.19)),
        at(0.0, 0.45, 0.0),
    );
    let leg = cuboid(Vec3::new(0.03, 0.21, 0.16));
    for x in [-0.58, 0.58] {
        append(&mut m, &leg, at(x, 0.21, 0.0));
    }
    append(
        &mut m,
        &cuboid(Vec3::new(0.55, 0.03, 0.025)),
        at(0.0, 0.12, 0.0),
    );
    m
}

/// A wooden crate with edge battens, `size` metres on a side, standing on y = 0.
pub(super) fn crate_mesh(size: f32) -> Mesh {
    let h = size * 0.5;
    let t = 0.025;
    let mut m = Mesh::default();
    append(&mut m, &cuboid(Vec3::splat(h - 0.01)), at(0.0, h, 0.0));
    for axis in 0..3 {
        let mut half = Vec3::splat(t);
        half[axis] = h;
        for (su, sv) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let mut c = Vec3::ZERO;
            c[(axis + 1) % 3] = su * (h - t);
            c[(axis + 2) % 3] = sv * (h - t);
            append(&mut m, &cuboid(half), at(c.x, c.y + h, c.z));
        }
    }
    m
}

fn crates(b: &mut SceneBuilder, p: &Palette) {
    let big = b.mesh(crate_mesh(0.6), "crate_large", p.wood);
    let mid = b.mesh(crate_mesh(0.5), "crate_medium", p.wood);
    let small = b.mesh(crate_mesh(0.4), "crate_small", p.wood);
    // South-west corner stack.
    b.place(big, at_yaw(-9.5, 0.0, 5.55, 0.0));
    b.place(big, at_yaw(-8.8, 0.0, 5.5, 8.0));
    b.place(mid, at_yaw(-9.45, 0.6, 5.5, -12.0));
    b.place(small, at_yaw(-9.5, 0.0, 4.85, 20.0));
    // North-east corner, between pilasters.
    b.place(big, at_yaw(7.0, 0.0, -5.55, -5.0));
    b.place(small, at_yaw(7.05, 0.6, -5.5, 15.0));
    b.place(small, at_yaw(7.1, 0.0, -4.85, 35.0));
}

fn barrels(b: &mut SceneBuilder, p: &Palette) {
    let v = Vec2::new;
    let mut profile = vec![v(0.0, 0.0)];
    for k in 0..=12 {
        let y = 0.9 * k as f32 / 12.0;
        profile.push(v(0.26 + 0.05 * (std::f32::consts::PI * y / 0.9).sin(), y));
    }
    profile.push(v(0.0, 0.9));
    let mut m = lathe(&profile, 40, 30.0);
    for y in [0.1, 0.75] {
        let bulge = 0.26 + 0.05 * (std::f32::consts::PI * y / 0.9).sin();
        let hoop = [
            v(bulge - 0.02, y),
            v(bulge + 0.012, y),
            v(bulge + 0.012, y + 0.05),
            v(bulge - 0.02, y + 0.05),
            v(bulge - 0.02, y),
        ];
        append(&mut m, &lathe(&hoop, 40, 0.0), at(0.0, 0.0, 0.0));
    }
    let barrel = b.mesh(m, "barrel", p.wood_dark);
    b.place(barrel, at_yaw(-9.55, 0.0, -5.55, 0.0));
    b.place(barrel, at_yaw(-8.9, 0.0, -5.6, 40.0));
    b.place(barrel, at_yaw(-9.5, 0.0, -4.9, 75.0));
}

/// An open vase of the given height and belly radius: foot, belly, neck, flared lip and a
/// shallow interior.
pub(super) fn vase_mesh(height: f32, belly: f32) -> Mesh {
    let v = Vec2::new;
    let neck = belly * 0.42;
    let foot = belly * 0.6;
    let mut profile = vec![
        v(0.0, 0.0),
        v(foot, 0.0),
        v(foot, 0.02 * height),
        v(neck * 1.1, 0.07 * height),
    ];
    // Belly from 0.07 h to 0.72 h.
    for k in 1..=14 {
        let t = k as f32 / 14.0;
        let r = neck * 1.1
            + (belly - neck * 1.1) * (std::f32::consts::PI * t).sin().powf(0.7) * (1.0 - 0.15 * t);
        profile.push(v(r.max(neck), (0.07 + 0.65 * t) * height));
    }
    // Neck and lip.
    profile.extend([
        v(neck, 0.85 * height),
        v(neck * 1.35, 0.97 * height),
        v(neck * 1.35, height),
        v(neck * 1.1, height),
        v(neck * 0.85, 0.86 * height),
        v(0.0, 0.86 * height),
    ]);
    lathe(&profile, 40, 35.0)
}

fn vases(b: &mut SceneBuilder, p: &Palette) {
    let tall = b.mesh(vase_mesh(0.9, 0.22), "amphora", p.glaze);
    let squat = b.mesh(vase_mesh(0.45, 0.18), "urn", p.terracotta);
    // Along the south wall between the pilasters.
    for x in [-5.0, -1.0, 3.0] {
        b.place(tall, at(x, 0.0, 5.7));
    }
    b.place(squat, at(-4.55, 0.0, 5.72));
    // At the feet of some columns, on the aisle side.
    for (x, z) in [
        (-6.0, ROW_Z + 0.62),
        (2.0, ROW_Z + 0.62),
        (-4.0, -ROW_Z - 0.62),
    ] {
        b.place(squat, at(x, 0.0, z));
    }
    // Flanking the dais stairs.
    for z in [-DAIS_HALF_Z + 0.3, DAIS_HALF_Z - 0.3] {
        b.place(squat, at(DAIS_X - 0.3, 0.0, z));
    }
}

/// The table in the nave with stools and objects on its top.
fn table(b: &mut SceneBuilder, p: &Palette) {
    let (hx, hz, t) = (0.8, 0.4, 0.04);
    let mut m = Mesh::default();
    append(
        &mut m,
        &cuboid(Vec3::new(hx, t * 0.5, hz)),
        at(0.0, TABLE_TOP - t * 0.5, 0.0),
    );
    let leg = cuboid(Vec3::new(0.03, (TABLE_TOP - t) * 0.5, 0.03));
    for (sx, sz) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
        append(
            &mut m,
            &leg,
            at(sx * (hx - 0.07), (TABLE_TOP - t) * 0.5, sz * (hz - 0.07)),
        );
    }
    let apron_y = TABLE_TOP - t - 0.05;
    for sz in [-1.0, 1.0] {
        append(
            &mut m,
            &cuboid(Vec3::new(hx - 0.1, 0.05, 0.01)),
            at(0.0, apron_y, sz * (hz - 0.07)),
        );
    }
    for sx in [-1.0, 1.0] {
        append(
            &mut m,
            &cuboid(Vec3::new(0.01, 0.05, hz - 0.1)),
            at(sx * (hx - 0.07), apron_y, 0.0),
        );
    }
    let table = b.mesh(m, "table", p.wood);
    b.place(table, at(TABLE_X, 0.0, 0.0));

    let mut stool = Mesh::default();
    append(&mut stool, &cylinder(0.17, 0.04, 32), at(0.0, 0.42, 0.0));
    let leg = cylinder(0.018, 0.42, 10);
    for k in 0..3 {
        let a = k as f32 * std::f32::consts::TAU / 3.0;
        append(&mut stool, &leg, at(0.11 * a.cos(), 0.0, 0.11 * a.sin()));
    }
    let stool = b.mesh(stool, "stool", p.wood_dark);
    b.place(stool, at(TABLE_X - 0.4, 0.0, -0.72));
    b.place(stool, at(TABLE_X + 0.35, 0.0, 0.74));

    // On the table top (the sliding box uses the strip z ∈ [0, 0.25], x < TABLE_X + 0.4).
    let small_vase = b.mesh(vase_mesh(0.28, 0.08), "small_vase", p.glass);
    b.place(small_vase, at(TABLE_X - 0.5, TABLE_TOP, -0.22));
    let v = Vec2::new;
    let bowl_profile = [
        v(0.0, 0.0),
        v(0.05, 0.0),
        v(0.05, 0.01),
        v(0.09, 0.025),
        v(0.115, 0.05),
        v(0.125, 0.07),
        v(0.115, 0.07),
        v(0.105, 0.052),
        v(0.08, 0.033),
        v(0.04, 0.02),
        v(0.0, 0.02),
    ];
    let bowl = b.mesh(lathe(&bowl_profile, 40, 35.0), "bowl", p.terracotta);
    b.place(bowl, at(TABLE_X + 0.6, TABLE_TOP, 0.18));
    let fruit = b.mesh(sphere(0.035, 20), "fruit", p.paint);
    for (dx, dy, dz) in [
        (0.0, 0.055, 0.0),
        (0.05, 0.064, 0.03),
        (-0.04, 0.064, 0.035),
    ] {
        b.place(fruit, at(TABLE_X + 0.6 + dx, TABLE_TOP + dy, 0.18 + dz));
    }
    let book = b.mesh(cuboid(Vec3::new(0.11, 0.02, 0.075)), "book", p.wood_dark);
    for (k, yaw) in [(0, 5.0), (1, -12.0), (2, 20.0)] {
        b.place(
            book,
            at_yaw(
                TABLE_X + 0.55,
                TABLE_TOP + 0.02 + 0.04 * k as f32,
                -0.2,
                yaw,
            ),
        );
    }
    let candle = b.mesh(cylinder(0.025, 0.18, 16), "candle", p.plaster);
    b.place(candle, at(TABLE_X, TABLE_TOP, -0.25));
}

/// Pedestals with stone balls and a large urn on the dais.
fn dais_ornaments(b: &mut SceneBuilder, p: &Palette) {
    let mut pedestal = Mesh::default();
    append(
        &mut pedestal,
        &cuboid(Vec3::new(0.2, 0.45, 0.2)),
        at(0.0, 0.45, 0.0),
    );
    append(
        &mut pedestal,
        &cuboid(Vec3::new(0.24, 0.04, 0.24)),
        at(0.0, 0.04, 0.0),
    );
    append(
        &mut pedestal,
        &cuboid(Vec3::new(0.24, 0.04, 0.24)),
        at(0.0, 0.86, 0.0),
    );
    let pedestal = b.mesh(pedestal, "pedestal", p.stone);
    let ball = b.mesh(sphere(0.18, 40), "chrome_ball", p.chrome);
    for z in [-1.7, 1.7] {
        b.place(pedestal, at(9.4, DAIS_TOP, z));
        b.place(ball, at(9.4, DAIS_TOP + 0.9 + 0.18, z));
    }
    let urn = b.mesh(vase_mesh(1.0, 0.3), "great_urn", p.terracotta);
    b.place(urn, at(9.3, DAIS_TOP, 0.0));
}
