//! Simulator and sensor configuration (`configs/sim.toml`, `configs/sensors.toml`).
//!
//! Every key has a default here, so a missing file or section means "the defaults"; the files in
//! `configs/` document each key.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use kitchen_r_core::GraspMode;

use crate::error::{SimError, read_toml};
use crate::robot::rmp::RmpParams;

/// Environment variable that overrides the configs directory.
pub const CONFIGS_ENV: &str = "KITCHEN_R_CONFIGS";

/// The configs directory: `KITCHEN_R_CONFIGS`, `./configs`, or the workspace's `configs/`.
pub fn configs_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os(CONFIGS_ENV) {
        return PathBuf::from(dir);
    }
    let local = PathBuf::from("configs");
    if local.join("sim.toml").is_file() {
        return local;
    }
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs"))
}

/// `configs/sim.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    pub physics: PhysicsConfig,
    pub rmp: RmpParams,
    pub success: SuccessConfig,
    pub monitors: MonitorConfig,
    pub grasp: GraspConfig,
    pub robot: RobotConfig,
    pub articulation: ArticulationConfig,
}

/// `[articulation]`: the force-limited fingers of the physical grasp mode
/// (`robot/articulated.rs`, docs/twin/robot.md); unused in the abstract mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArticulationConfig {
    /// Finger motors: the largest squeezing force of each finger (N), and the servo's stiffness
    /// (N/m) and damping (N·s/m) towards the commanded gap.
    pub finger_force: f64,
    pub finger_stiffness: f64,
    pub finger_damping: f64,
    /// How far past the pads' meeting point each closed finger's servo target lies (m): an
    /// object thinner than the servo needs to build its force (a plate's 4 mm rim) is squeezed
    /// with `finger_stiffness` × (half its width + this), up to `finger_force`. The joint's
    /// limit stays at the meeting point, so fingers closed on nothing stop there.
    pub finger_preload: f64,
    /// Coulomb friction of the finger pads (combined with the object's by averaging).
    pub finger_friction: f64,
    /// Mass of each finger (kg): the few constraint iterations converge differently with it (a
    /// held bowl crept 2 mm/s down 0.03 kg pads and not down 0.06 kg ones; docs/twin/robot.md).
    pub finger_mass: f64,
    /// Natural frequency of the contact softness (Hz; rapier's default is 30): stiffer contacts
    /// keep squeezed light objects from sinking millimetres into the fingers; 120 Hz let a held
    /// bowl rattle in the pads with a single 10 ms solver substep.
    pub contact_frequency: f64,
    /// Rapier's solver in this mode: substeps per physics step (`num_solver_iterations`; each
    /// rebuilds and factorises the fingers' mass matrix) and constraint
    /// iterations per substep (`num_internal_pgs_iterations`). The abstract mode keeps
    /// `[physics] solver_iterations` substeps of one iteration each.
    pub solver_iterations: u32,
    pub pgs_iterations: u32,
}

impl Default for ArticulationConfig {
    fn default() -> Self {
        ArticulationConfig {
            finger_force: 15.0,
            finger_stiffness: 8000.0,
            finger_damping: 44.0,
            finger_preload: 0.002,
            finger_friction: 1.0,
            finger_mass: 0.06,
            contact_frequency: 60.0,
            solver_iterations: 2,
            pgs_iterations: 8,
        }
    }
}

/// `[robot]`: which robot the twin builds (docs/twin/robot.md).
/// [`Assets::load`](crate::Assets::load) reads it from `configs/sim.toml`, so the spawner, the
/// controller and the oracle all get it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotConfig {
    /// A URDF (`.urdf`) or MJCF (`.xml`) description with its sidecar TOML beside it, or a
    /// mounting sidecar (`.toml`, e.g. `configs/robots/robosuite/panda.toml`), relative to the
    /// assets directory or absolute. `KITCHEN_R_ROBOT` and `kitchen-r eval --robot` override it.
    pub file: PathBuf,
}

/// The robot file a command line chose (`--robot`), over `KITCHEN_R_ROBOT` and the config.
static ROBOT_OVERRIDE: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Make every [`SimConfig::load_default`] of this process build the robot `file` (a command's
/// `--robot` flag); `false` if another was set before.
pub fn override_robot(file: PathBuf) -> bool {
    ROBOT_OVERRIDE.set(file).is_ok()
}

impl RobotConfig {
    /// The config's robot with the command line's or `KITCHEN_R_ROBOT`'s choice applied (flags
    /// over environment over file).
    fn layered(mut self) -> RobotConfig {
        if let Some(f) = ROBOT_OVERRIDE.get() {
            self.file = f.clone();
        } else if let Some(f) = std::env::var_os("KITCHEN_R_ROBOT").filter(|f| !f.is_empty()) {
            self.file = PathBuf::from(f);
        }
        self
    }
}

impl Default for RobotConfig {
    fn default() -> Self {
        RobotConfig {
            file: PathBuf::from(kitchen_r_core::robot::SHIPPED),
        }
    }
}

impl RobotConfig {
    /// The description's path, with the assets directory `assets`.
    pub fn path(&self, assets: &Path) -> PathBuf {
        kitchen_r_core::robot::resolve(assets, &self.file)
    }
}

/// `[grasp]`: how the gripper holds objects (docs/twin/robot.md). The organiser's contest setting,
/// when a job carries one, overrides this file's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct GraspConfig {
    pub mode: GraspMode,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PhysicsConfig {
    /// Control period: one action per control step (s).
    pub control_dt: f64,
    /// Physics substeps per control step.
    pub substeps: u32,
    /// Solver iterations per substep.
    pub solver_iterations: u32,
    pub gravity: f64,
}

impl Default for PhysicsConfig {
    fn default() -> Self {
        PhysicsConfig {
            control_dt: 0.1,
            substeps: 10,
            solver_iterations: 4,
            gravity: -9.81,
        }
    }
}

impl PhysicsConfig {
    pub fn dt(&self) -> f64 {
        self.control_dt / f64::from(self.substeps)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SuccessConfig {
    /// Navigation: base centre within this distance of the target (m).
    pub navigation_tolerance: f64,
    /// Manipulation: object centre within this distance of its target (m).
    pub manipulation_tolerance: f64,
    /// A pick counts once the held object's bottom is this far above its support (m).
    pub lift_clearance: f64,
}

impl Default for SuccessConfig {
    fn default() -> Self {
        SuccessConfig {
            navigation_tolerance: 0.10,
            manipulation_tolerance: 0.05,
            lift_clearance: 0.03,
        }
    }
}

/// Monitoring Module thresholds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MonitorConfig {
    /// Per-action sim-time limits (s).
    pub move_time_limit: f64,
    pub pick_time_limit: f64,
    pub place_time_limit: f64,
    /// A key object whose centre is lower than this above the floor has fallen (m).
    pub floor_height: f64,
    /// At the end of a pick the TCP must be this close to the object's grasp point (m).
    pub pick_gripper_distance: f64,
    /// After a place the object's centre must be this close to the goal (m).
    pub place_goal_distance: f64,
    /// After a move the base centre must lie inside this circle around the goal (m).
    pub move_goal_radius: f64,
}

impl Default for MonitorConfig {
    fn default() -> Self {
        MonitorConfig {
            move_time_limit: 120.0,
            pick_time_limit: 120.0,
            place_time_limit: 120.0,
            floor_height: 0.15,
            pick_gripper_distance: 0.06,
            place_goal_distance: 0.05,
            move_goal_radius: 0.10,
        }
    }
}

impl SimConfig {
    pub fn load(path: &Path) -> Result<SimConfig, SimError> {
        let c: SimConfig = read_toml(path)?;
        c.validate()?;
        Ok(c)
    }

    /// `configs/sim.toml` when present, else the defaults.
    pub fn load_default() -> Result<SimConfig, SimError> {
        let path = configs_dir().join("sim.toml");
        let mut config = if path.is_file() {
            SimConfig::load(&path)?
        } else {
            SimConfig::default()
        };
        config.robot = config.robot.layered();
        Ok(config)
    }

    pub fn validate(&self) -> Result<(), SimError> {
        let p = &self.physics;
        if p.control_dt.is_nan() || p.control_dt <= 0.0 || p.substeps == 0 || p.solver_iterations == 0 {
            return Err(SimError::Config(
                "physics: control_dt > 0, substeps >= 1, solver_iterations >= 1".into(),
            ));
        }
        let a = &self.articulation;
        let gains = [
            a.finger_force,
            a.finger_stiffness,
            a.finger_damping,
            a.finger_mass,
            a.contact_frequency,
        ];
        if gains.iter().any(|v| v.is_nan() || *v <= 0.0)
            || a.finger_friction.is_nan()
            || a.finger_friction < 0.0
            || a.finger_preload.is_nan()
            || a.finger_preload < 0.0
            || a.solver_iterations == 0
            || a.pgs_iterations == 0
        {
            return Err(SimError::Config(
                "articulation: gains, force, finger mass and contact frequency > 0, finger_friction and finger_preload >= 0, \
                 solver_iterations and pgs_iterations >= 1"
                    .into(),
            ));
        }
        Ok(())
    }
}

/// `configs/sensors.toml`: cameras and LiDAR.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorsConfig {
    #[serde(rename = "camera")]
    pub cameras: Vec<CameraConfig>,
    pub lidar: Option<LidarConfig>,
    pub light: LightConfig,
}

/// What a sensor is rigidly attached to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mount {
    /// The robot base frame.
    Base,
    /// The gripper's TCP frame.
    Gripper,
    /// The world frame (a fixed camera).
    World,
}

/// A pinhole camera looking along its local +x (y left, z up), like a robot link frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    pub name: String,
    pub mount: Mount,
    /// Position in the mount frame (m).
    pub position: [f64; 3],
    /// Roll, pitch, yaw in the mount frame (rad); positive pitch looks down.
    pub rpy: [f64; 3],
    pub width: u32,
    pub height: u32,
    /// Horizontal field of view (degrees).
    pub fov_deg: f64,
    /// Depth beyond this reads 0 (no return), metres.
    pub max_depth: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LidarConfig {
    pub mount: Mount,
    pub position: [f64; 3],
    /// Beams per revolution.
    pub beams: u32,
    /// Elevation of each channel (degrees); `[0.0]` is a planar scanner.
    pub channels_deg: Vec<f64>,
    pub min_range: f64,
    pub max_range: f64,
}

/// Simple lighting for the RGB images: ambient plus one directional light (Lambert).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LightConfig {
    /// Direction towards the light, world frame.
    pub direction: [f64; 3],
    pub ambient: f64,
    pub diffuse: f64,
}

impl Default for LightConfig {
    fn default() -> Self {
        LightConfig {
            direction: [0.35, 0.25, 1.0],
            ambient: 0.45,
            diffuse: 0.6,
        }
    }
}

impl Default for SensorsConfig {
    fn default() -> Self {
        let cam = |name: &str, mount, position, rpy| CameraConfig {
            name: name.into(),
            mount,
            position,
            rpy,
            width: 128,
            height: 128,
            fov_deg: 80.0,
            max_depth: 10.0,
        };
        SensorsConfig {
            cameras: vec![
                cam("base", Mount::Base, [0.0, 0.0, 1.35], [0.0, 0.55, 0.0]),
                cam("gripper", Mount::Gripper, [-0.06, 0.0, 0.07], [0.0, 0.45, 0.0]),
            ],
            lidar: Some(LidarConfig {
                mount: Mount::Base,
                position: [0.0, 0.0, 0.36],
                beams: 360,
                channels_deg: vec![0.0],
                min_range: 0.05,
                max_range: 8.0,
            }),
            light: LightConfig::default(),
        }
    }
}

impl SensorsConfig {
    pub fn load(path: &Path) -> Result<SensorsConfig, SimError> {
        let c: SensorsConfig = read_toml(path)?;
        c.validate()?;
        Ok(c)
    }

    /// `configs/sensors.toml` when present, else the defaults.
    pub fn load_default() -> Result<SensorsConfig, SimError> {
        let path = configs_dir().join("sensors.toml");
        if path.is_file() {
            SensorsConfig::load(&path)
        } else {
            Ok(SensorsConfig::default())
        }
    }

    pub fn validate(&self) -> Result<(), SimError> {
        for c in &self.cameras {
            if c.width == 0 || c.height == 0 || !(c.fov_deg > 0.0 && c.fov_deg < 179.0) {
                return Err(SimError::Config(format!("camera {:?}: bad size or fov", c.name)));
            }
        }
        if let Some(l) = &self.lidar
            && (l.beams == 0 || l.channels_deg.is_empty() || l.max_range <= l.min_range)
        {
            return Err(SimError::Config("lidar: beams, channels and ranges".into()));
        }
        Ok(())
    }
}
