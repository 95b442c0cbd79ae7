//! `kitchen-r sim …` and `kitchen-r bench sim`: the kitchen twin's tools. Argument parsing only;
//! the work is in `kitchen_r_sim`. `kitchen-r bench load` (the server under load) lives in
//! `load_bench`.

use std::path::PathBuf;

use clap::{Args, Subcommand};

#[derive(Args, Debug)]
pub(crate) struct SimArgs {
    #[command(subcommand)]
    pub command: SimCommand,
}

#[derive(Subcommand, Debug)]
pub(crate) enum SimCommand {
    /// Write every camera's RGB and depth (from the start and each zone's approach point) and a
    /// top-down view of a scene as PNG; or, with --episodes-file and --sheet, one contact sheet
    /// of a saved batch's first base-camera frames.
    Render {
        /// Scene id (file stem under assets/scenes).
        #[arg(long, required_unless_present = "episodes_file", requires = "out")]
        scene: Option<String>,
        /// Output directory (created if missing).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Seed for the robot start and background objects.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// A saved batch (`kitchen-r episodes generate`) to draw a contact sheet of.
        #[arg(long, value_name = "FILE", conflicts_with = "scene", requires = "sheet")]
        episodes_file: Option<PathBuf>,
        /// The contact sheet PNG: the first base-camera frame of each of the first --count
        /// episodes, four to a row.
        #[arg(long, value_name = "PNG")]
        sheet: Option<PathBuf>,
        /// Episodes on the contact sheet.
        #[arg(long, default_value_t = 8)]
        count: usize,
    },
    /// Write a scene as USD ASCII (furniture, key objects at their starts, zones as guide
    /// markers, the robot base) so Isaac Sim and other USD tools can open it.
    Export {
        /// Scene id (file stem under assets/scenes).
        #[arg(long)]
        scene: String,
        /// The `.usda` file to write.
        #[arg(long, value_name = "OUT.usda")]
        usd: PathBuf,
    },
}

#[derive(Args, Debug)]
pub(crate) struct BenchArgs {
    #[command(subcommand)]
    pub command: BenchCommand,
}

#[derive(Subcommand, Debug)]
pub(crate) enum BenchCommand {
    /// Simulator figures: physics step, observation time, real-time factor.
    Sim {
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
        /// Control steps to run.
        #[arg(long, default_value_t = 600)]
        steps: u32,
        /// Observe every this many control steps (the policy query rate).
        #[arg(long, default_value_t = 8)]
        query_every: u32,
        /// Also time the physics step (both grasp modes) and the observation with this robot (a
        /// URDF or MJCF description or a mounting sidecar, e.g.
        /// configs/robots/robosuite/panda.toml: a seven-joint arm of mesh links in the cameras'
        /// view)
        #[arg(long, value_name = "FILE")]
        mesh_robot: Option<std::path::PathBuf>,
    },
    /// The server under deadline-hour load: seed N plan submissions across T teams, then R
    /// leaderboard readers and U uploads/s for D seconds on loopback; latency percentiles and
    /// throughput of both sides, lost uploads, database size per submission.
    Load(crate::load_bench::LoadArgs),
}

pub(crate) fn sim(args: SimArgs) -> anyhow::Result<()> {
    match args.command {
        SimCommand::Export { scene, usd } => {
            kitchen_r_sim::usd_export::export_scene(&scene, &usd)?;
            println!("{}", usd.display());
            Ok(())
        }
        SimCommand::Render {
            scene,
            out,
            seed,
            episodes_file,
            sheet,
            count,
        } => {
            if let (Some(file), Some(sheet)) = (episodes_file, sheet) {
                let batch = kitchen_r_sim::episode::load_batch(&file)?;
                if batch.is_empty() || count == 0 {
                    anyhow::bail!("{}: no episodes to draw", file.display());
                }
                kitchen_r_sim::render::batch_sheet(&batch, count, &sheet)?;
                println!("{}", sheet.display());
                return Ok(());
            }
            let (Some(scene), Some(out)) = (scene, out) else {
                anyhow::bail!("sim render needs --scene and --out, or --episodes-file and --sheet");
            };
            for path in kitchen_r_sim::render::render_scene(&scene, &out, seed)? {
                println!("{}", path.display());
            }
            Ok(())
        }
    }
}

pub(crate) fn bench(args: BenchArgs) -> anyhow::Result<()> {
    match args.command {
        BenchCommand::Load(args) => crate::load_bench::run(args),
        BenchCommand::Sim {
            json,
            steps,
            query_every,
            mesh_robot,
        } => {
            // Relative to the working directory, as `eval --robot` reads it.
            let mesh_robot = mesh_robot.map(std::path::absolute).transpose()?;
            let r = kitchen_r_sim::bench::run(steps.max(1), query_every.max(1), mesh_robot.as_deref())?;
            if json {
                println!("{}", r.to_json());
            } else {
                println!("scene                 {}", r.scene);
                println!(
                    "physics_step_us       {:.1} (median of 5 batches; fastest {:.1})",
                    r.physics_step_us, r.physics_step_us_min
                );
                println!(
                    "physics_step_us (physical grasp) {:.1} (fastest {:.1})",
                    r.physics_step_us_articulated, r.physics_step_us_articulated_min
                );
                println!("control_step_us       {:.1}", r.control_step_us);
                println!(
                    "observation_ms        {:.2} ({} cameras, {} px; median of 5 batches; fastest {:.2})",
                    r.observation_ms, r.cameras, r.camera_pixels, r.observation_ms_min
                );
                println!("rays_per_second       {:.0}", r.rays_per_second);
                println!(
                    "realtime_factor       {:.1} (observe every {} steps)",
                    r.realtime_factor, r.query_every
                );
                if let Some(m) = &r.mesh_robot {
                    println!(
                        "mesh robot            {} ({} arm joints, {} arm colliders)",
                        m.robot, m.arm_joints, m.arm_colliders
                    );
                    println!(
                        "  physics_step_us     {:.1} (fastest {:.1})",
                        m.physics_step_us, m.physics_step_us_min
                    );
                    println!(
                        "  physics_step_us (physical grasp) {:.1} (fastest {:.1})",
                        m.physics_step_us_articulated, m.physics_step_us_articulated_min
                    );
                    println!(
                        "  observation_ms      {:.2} ({} cameras, robot in view; fastest {:.2})",
                        m.observation_ms, m.cameras, m.observation_ms_min
                    );
                }
            }
            Ok(())
        }
    }
}
