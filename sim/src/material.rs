//! Render materials and the tags that tie a collider back to what it is.
//!
//! A collider's `user_data` packs its material index (bits 0..32), what it belongs to
//! ([`Owner`], bits 32..40) and that owner's index (bits 40..72). The renderer reads the material,
//! contact reporting and success checks read the owner.

use rapier3d::prelude::{Group, InteractionGroups, InteractionTestMode};
use serde::{Deserialize, Serialize};

/// Surface pattern, evaluated at the world hit point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Pattern {
    Plain,
    /// Square tiles of this size with alternating brightness (floors).
    Tiles {
        size: f32,
        contrast: f32,
    },
    /// Horizontal bands of this height (walls, wood grain).
    Stripes {
        size: f32,
        contrast: f32,
    },
    /// Cubes of this size with alternating brightness in all three axes (check floors, tiled
    /// walls and fronts).
    Checker {
        size: f32,
        contrast: f32,
    },
    /// Boards of this width along x and y alike (floorboards, vertical panels).
    Planks {
        size: f32,
        contrast: f32,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// sRGB in [0, 1].
    pub color: [f32; 3],
    pub pattern: Pattern,
}

impl Material {
    pub fn plain(color: [f32; 3]) -> Material {
        Material {
            color,
            pattern: Pattern::Plain,
        }
    }

    /// Albedo at world point `p`.
    #[inline]
    pub fn albedo(&self, p: [f32; 3]) -> [f32; 3] {
        let k = match self.pattern {
            Pattern::Plain => 1.0,
            Pattern::Tiles { size, contrast } => {
                let (x, y) = (p[0] / size, p[1] / size);
                let (i, j) = (floor(x) as i64, floor(y) as i64);
                let grout = fract(x).abs() < 0.03 || fract(y).abs() < 0.03;
                if grout {
                    1.0 - 2.0 * contrast
                } else if (i + j) % 2 == 0 {
                    1.0
                } else {
                    1.0 - contrast
                }
            }
            Pattern::Stripes { size, contrast } => {
                if (floor(p[2] / size) as i64) % 2 == 0 {
                    1.0
                } else {
                    1.0 - contrast
                }
            }
            Pattern::Checker { size, contrast } => {
                let cell = |v: f32| floor(v / size) as i64;
                if (cell(p[0]) + cell(p[1]) + cell(p[2])).rem_euclid(2) == 0 {
                    1.0
                } else {
                    1.0 - contrast
                }
            }
            Pattern::Planks { size, contrast } => {
                let board = floor((p[0] + p[1]) / size) as i64;
                // Three shades cycle so neighbouring boards always differ.
                1.0 - contrast * (board.rem_euclid(3) as f32) / 2.0
            }
        };
        self.color.map(|c| (c * k).clamp(0.0, 1.0))
    }
}

/// `f32::trunc` without the libm call (x86-64 without SSE4.1 has no rounding instruction, and
/// the renderer calls this per pixel); exact wherever an `i32` holds the value.
#[inline]
fn trunc(x: f32) -> f32 {
    if x.abs() < 2_147_483_520.0 {
        x as i32 as f32
    } else {
        x.trunc()
    }
}

/// `f32::floor`, the same way.
#[inline]
fn floor(x: f32) -> f32 {
    let t = trunc(x);
    if x < t { t - 1.0 } else { t }
}

/// `f32::fract` (`x - x.trunc()`), the same way.
#[inline]
fn fract(x: f32) -> f32 {
    x - trunc(x)
}

/// What a collider belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Owner {
    /// Walls, floor, furniture.
    Static,
    /// Key object by index in the episode's object list.
    KeyObject,
    Background,
    /// Robot part by index (see `robot::parts`).
    Robot,
    /// Purely visual detail (handles, seams): never collides.
    Decoration,
}

impl Owner {
    fn code(self) -> u128 {
        match self {
            Owner::Static => 0,
            Owner::KeyObject => 1,
            Owner::Background => 2,
            Owner::Robot => 3,
            Owner::Decoration => 4,
        }
    }

    fn from_code(c: u128) -> Owner {
        match c {
            1 => Owner::KeyObject,
            2 => Owner::Background,
            3 => Owner::Robot,
            4 => Owner::Decoration,
            _ => Owner::Static,
        }
    }

    /// Collision groups: key objects ignore the fingers (a grasp attaches them instead of
    /// squeezing), robot parts ignore each other, decorations ignore everything.
    pub fn groups(self, finger: bool) -> InteractionGroups {
        let (member, filter) = match (self, finger) {
            (Owner::Robot, true) => (FINGER, STATIC | BACKGROUND),
            (Owner::Robot, false) => (ROBOT, STATIC | KEY | BACKGROUND),
            (Owner::Static, _) => (STATIC, Group::ALL),
            (Owner::KeyObject, _) => (KEY, STATIC | KEY | BACKGROUND | ROBOT),
            (Owner::Background, _) => (BACKGROUND, Group::ALL),
            (Owner::Decoration, _) => (DECORATION, Group::NONE),
        };
        InteractionGroups::new(member, filter, InteractionTestMode::And)
    }

    /// The physical grasp mode's fingers also touch key objects: friction holds them.
    pub fn physical_finger_groups(self) -> InteractionGroups {
        InteractionGroups::new(FINGER, STATIC | KEY | BACKGROUND, InteractionTestMode::And)
    }

    /// A key object in the physical grasp mode: touched by the fingers as well.
    pub fn physical_key_groups(self) -> InteractionGroups {
        InteractionGroups::new(
            KEY,
            STATIC | KEY | BACKGROUND | ROBOT | FINGER,
            InteractionTestMode::And,
        )
    }

    /// A held key object touches neither the robot's links nor its fingers (the grasp joint holds
    /// it), only the scene and other objects.
    pub fn held_groups(self) -> InteractionGroups {
        InteractionGroups::new(KEY, STATIC | KEY | BACKGROUND, InteractionTestMode::And)
    }
}

const STATIC: Group = Group::GROUP_1;
const KEY: Group = Group::GROUP_2;
const BACKGROUND: Group = Group::GROUP_3;
const ROBOT: Group = Group::GROUP_4;
const FINGER: Group = Group::GROUP_5;
const DECORATION: Group = Group::GROUP_6;

/// Packed collider tag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Tag {
    pub material: u32,
    pub owner: Owner,
    pub index: u32,
}

impl Tag {
    pub fn pack(self) -> u128 {
        u128::from(self.material) | (self.owner.code() << 32) | (u128::from(self.index) << 40)
    }

    pub fn unpack(v: u128) -> Tag {
        Tag {
            material: (v & 0xffff_ffff) as u32,
            owner: Owner::from_code((v >> 32) & 0xff),
            index: ((v >> 40) & 0xffff_ffff) as u32,
        }
    }
}

/// The material table of one world.
#[derive(Debug, Clone, Default)]
pub struct Materials {
    pub list: Vec<Material>,
}

impl Materials {
    pub fn add(&mut self, m: Material) -> u32 {
        if let Some(i) = self.list.iter().position(|x| *x == m) {
            return i as u32;
        }
        self.list.push(m);
        (self.list.len() - 1) as u32
    }
}

/// Blend two colours: `t = 0` gives `a`.
pub fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [0, 1, 2].map(|i| a[i] * (1.0 - t) + b[i] * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_rounding_matches_the_standard_library() {
        let mut x = -70_000.0f32;
        while x < 70_000.0 {
            for v in [x, x + 0.5, x - 1e-3, x + 0.999, -x] {
                assert_eq!(trunc(v), v.trunc(), "{v}");
                assert_eq!(floor(v), v.floor(), "{v}");
                assert_eq!(fract(v), v.fract(), "{v}");
            }
            x += 0.37;
        }
        for v in [3e9f32, -3e9, f32::MAX, f32::MIN, 0.0, -0.0, 1e-30, -1e-30] {
            assert_eq!(floor(v), v.floor(), "{v}");
            assert_eq!(fract(v), v.fract(), "{v}");
        }
        assert!(floor(f32::NAN).is_nan() && fract(f32::INFINITY).is_nan());
    }
}
