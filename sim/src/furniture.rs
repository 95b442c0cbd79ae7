//! How each furniture kind is built out of boxes. The scene file gives only the outer box, pose,
//! scale and colour; the parts (counter top, legs, shelf boards, sink basin, door seams and
//! handles) are derived here so the cameras see recognisable furniture. Furniture read from USD
//! brings its own boxes, which are used as they are.

use kitchen_r_core::scene::{Furniture, FurnitureKind, Scene};

use crate::material::mix;

/// One box of a furniture item, in the item's local frame (origin at the footprint centre on the
/// floor, x along `size[0]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    pub center: [f64; 3],
    pub half: [f64; 3],
    pub color: [f32; 3],
    /// Visual only (never collides).
    pub decoration: bool,
}

const TOP: f64 = 0.04;
const DARK: [f32; 3] = [0.12, 0.12, 0.13];
const METAL: [f32; 3] = [0.72, 0.73, 0.75];
const STONE: [f32; 3] = [0.86, 0.85, 0.82];

fn part(center: [f64; 3], size: [f64; 3], color: [f32; 3]) -> Part {
    Part {
        center,
        half: size.map(|s| s / 2.0),
        color,
        decoration: false,
    }
}

fn deco(center: [f64; 3], size: [f64; 3], color: [f32; 3]) -> Part {
    Part {
        decoration: true,
        ..part(center, size, color)
    }
}

/// Local unit direction (`[±1, 0]` or `[0, ±1]`) of the item's open front: towards the approach
/// point of a zone on it, else towards the room centre.
pub fn front(scene: &Scene, f: &Furniture) -> [f64; 2] {
    let target = scene
        .zones
        .iter()
        .find(|z| z.furniture == f.id)
        .map(|z| [z.approach[0], z.approach[1]])
        .unwrap_or([scene.room.size[0] / 2.0, scene.room.size[1] / 2.0]);
    let (dx, dy) = (target[0] - f.pose[0], target[1] - f.pose[1]);
    let (s, c) = f.pose[2].sin_cos();
    let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
    let [sx, sy, _] = f.scaled_size();
    if lx.abs() / sx >= ly.abs() / sy {
        [lx.signum(), 0.0]
    } else {
        [0.0, ly.signum()]
    }
}

/// Map a point given as (along the front face, out of the front face, height) to local xyz.
struct FrontFrame {
    front: [f64; 2],
    depth: f64,
}

impl FrontFrame {
    fn at(&self, along: f64, out: f64, z: f64) -> [f64; 3] {
        let [fx, fy] = self.front;
        let d = self.depth / 2.0 + out;
        [fx * d - fy * along, fy * d + fx * along, z]
    }

    /// A box size given as (along, out, height) in local axes.
    fn size(&self, along: f64, out: f64, h: f64) -> [f64; 3] {
        if self.front[0] != 0.0 {
            [out, along, h]
        } else {
            [along, out, h]
        }
    }
}

/// All parts of one item: its own boxes when it has them (furniture read from USD), else those
/// derived from its kind.
pub fn parts(scene: &Scene, f: &Furniture) -> Vec<Part> {
    // A mesh item is its mesh (`world::build_static`), nothing derived.
    if f.mesh.is_some() {
        return Vec::new();
    }
    if !f.parts.is_empty() {
        return f
            .parts
            .iter()
            .map(|b| Part {
                center: b.center,
                half: b.size.map(|s| s / 2.0),
                color: b.color,
                decoration: b.decoration,
            })
            .collect();
    }
    let [sx, sy, h] = f.scaled_size();
    let fr = front(scene, f);
    let (width, depth) = if fr[0] != 0.0 { (sy, sx) } else { (sx, sy) };
    let ff = FrontFrame { front: fr, depth };
    let c = f.color;
    match f.kind {
        FurnitureKind::Counter | FurnitureKind::Cabinet | FurnitureKind::Stove => {
            let mut p = cabinet(&ff, sx, sy, h, width, c);
            if f.kind == FurnitureKind::Stove {
                for (a, o) in [(-0.15f64, -0.15f64), (0.15, -0.15), (-0.15, -0.4), (0.15, -0.4)] {
                    if a.abs() < width / 2.0 && -o < depth {
                        p.push(deco(ff.at(a, o, h + 0.004), ff.size(0.18, 0.18, 0.008), DARK));
                    }
                }
            }
            p
        }
        FurnitureKind::Sink => sink(&ff, sx, sy, h, width, depth, c),
        FurnitureKind::Table => table(sx, sy, h, c),
        FurnitureKind::Shelf => shelf(&ff, f, sx, sy, h, width, depth, c),
        FurnitureKind::Fridge => {
            let mut p = vec![part([0.0, 0.0, h / 2.0], [sx, sy, h], c)];
            p.push(deco(
                ff.at(0.0, 0.003, h * 0.62),
                ff.size(width - 0.02, 0.008, 0.012),
                DARK,
            ));
            for z in [h * 0.8, h * 0.35] {
                p.push(deco(
                    ff.at(width / 2.0 - 0.08, 0.02, z),
                    ff.size(0.025, 0.03, 0.3),
                    METAL,
                ));
            }
            p
        }
    }
}

fn cabinet(ff: &FrontFrame, sx: f64, sy: f64, h: f64, width: f64, c: [f32; 3]) -> Vec<Part> {
    let mut p = vec![
        part([0.0, 0.0, (h - TOP) / 2.0], [sx, sy, h - TOP], c),
        part([0.0, 0.0, h - TOP / 2.0], [sx, sy, TOP], mix(c, STONE, 0.8)),
        deco(
            ff.at(0.0, 0.003, 0.05),
            ff.size(width, 0.008, 0.1),
            mix(c, DARK, 0.6),
        ),
    ];
    let doors = (width / 0.5).round().max(1.0) as usize;
    let w = width / doors as f64;
    for i in 0..doors {
        let a = -width / 2.0 + w * (i as f64 + 0.5);
        if i > 0 {
            p.push(deco(
                ff.at(a - w / 2.0, 0.003, h / 2.0),
                ff.size(0.01, 0.008, h - 0.2),
                DARK,
            ));
        }
        p.push(deco(
            ff.at(a + w * 0.3, 0.012, h - 0.14),
            ff.size(0.12, 0.02, 0.02),
            METAL,
        ));
    }
    p
}

fn sink(ff: &FrontFrame, sx: f64, sy: f64, h: f64, width: f64, depth: f64, c: [f32; 3]) -> Vec<Part> {
    let mut p = vec![part([0.0, 0.0, (h - 0.2) / 2.0], [sx, sy, h - 0.2], c)];
    let (bw, bd) = ((width - 0.2).max(0.2), (depth - 0.2).max(0.2));
    let rim = mix(c, METAL, 0.7);
    // Top ring around the basin: front and back strips, left and right strips.
    let strip_d = (depth - bd) / 2.0;
    let strip_w = (width - bw) / 2.0;
    // The strips reach down to the carcass so their inner faces are the basin walls.
    let z = h - 0.1;
    p.push(part(
        ff.at(0.0, -strip_d / 2.0, z),
        ff.size(width, strip_d, 0.2),
        rim,
    ));
    p.push(part(
        ff.at(0.0, -depth + strip_d / 2.0, z),
        ff.size(width, strip_d, 0.2),
        rim,
    ));
    for s in [-1.0, 1.0] {
        p.push(part(
            ff.at(s * (width - strip_w) / 2.0, -depth / 2.0, z),
            ff.size(strip_w, bd, 0.2),
            rim,
        ));
    }
    // Basin walls and bottom, 0.16 m deep.
    let bz = h - 0.2;
    p.push(part(
        ff.at(0.0, -depth / 2.0, bz + 0.01),
        ff.size(bw, bd, 0.02),
        mix(METAL, DARK, 0.3),
    ));
    p.push(deco(
        ff.at(0.0, -depth + 0.06, h + 0.12),
        ff.size(0.03, 0.03, 0.24),
        METAL,
    ));
    p.push(deco(
        ff.at(0.0, -depth + 0.12, h + 0.23),
        ff.size(0.03, 0.14, 0.025),
        METAL,
    ));
    p.push(deco(
        ff.at(0.0, 0.003, h / 2.0),
        ff.size(0.01, 0.008, h - 0.3),
        DARK,
    ));
    p
}

fn table(sx: f64, sy: f64, h: f64, c: [f32; 3]) -> Vec<Part> {
    let mut p = vec![part([0.0, 0.0, h - TOP / 2.0], [sx, sy, TOP], c)];
    let leg = 0.05;
    for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let x = a * (sx / 2.0 - leg);
        let y = b * (sy / 2.0 - leg);
        p.push(part(
            [x, y, (h - TOP) / 2.0],
            [leg, leg, h - TOP],
            mix(c, DARK, 0.3),
        ));
    }
    p
}

#[allow(clippy::too_many_arguments)]
fn shelf(
    ff: &FrontFrame,
    f: &Furniture,
    sx: f64,
    sy: f64,
    h: f64,
    width: f64,
    depth: f64,
    c: [f32; 3],
) -> Vec<Part> {
    let t = 0.02;
    let mut p = vec![part(
        ff.at(0.0, -depth + t / 2.0, h / 2.0),
        ff.size(width, t, h),
        mix(c, DARK, 0.2),
    )];
    for s in [-1.0, 1.0] {
        p.push(part(
            ff.at(s * (width - t) / 2.0, -depth / 2.0, h / 2.0),
            ff.size(t, depth, h),
            c,
        ));
    }
    let mut levels: Vec<f64> = f.levels.iter().map(|l| l * f.scale).collect();
    levels.push(h);
    levels.push(t + 0.08);
    for l in levels {
        p.push(part(
            [0.0, 0.0, l - t / 2.0],
            [sx, sy, t].map(|v| v - 0.001),
            mix(c, STONE, 0.15),
        ));
    }
    p
}
