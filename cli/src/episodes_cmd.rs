//! `kitchen-r episodes …`: saved batches of validation episode configurations (paper, BASELINE
//! VALIDATION steps 1–2) that `eval --episodes-file` runs exactly. Argument parsing and printing;
//! the draws are in `kitchen_r_sim::generator` and `kitchen_r_sim::randomise`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use kitchen_r_core::dataset::{Instruction, read_jsonl};
use kitchen_r_episode::samples::instruction_episode;
use kitchen_r_sim::episode::{load_batch, save_batch};
use kitchen_r_sim::material::Pattern;
use kitchen_r_sim::randomise::generate_varied;
use kitchen_r_sim::seeds::{instruction_seed, sub_seed};
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams};

#[derive(Args, Debug)]
pub(crate) struct EpisodesArgs {
    #[command(subcommand)]
    command: EpisodesCommand,
}

#[derive(Subcommand, Debug)]
enum EpisodesCommand {
    /// Write a batch of episode configurations (JSON): generated single-object episodes, or
    /// episodes of dataset instructions (--from-dataset), randomised as configs/episodes.toml's
    /// [randomise] says.
    Generate(GenerateArgs),
    /// One line per episode of a saved batch.
    Show {
        /// The batch (JSON written by `episodes generate`).
        file: PathBuf,
    },
}

#[derive(Args, Debug)]
struct GenerateArgs {
    /// Episodes to write.
    #[arg(long)]
    count: usize,
    /// Batch seed: episode i of a batch is the same whatever --count is.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output file (JSON array of episode configurations).
    #[arg(long)]
    out: PathBuf,
    /// Episodes of dataset instructions (cycled in file order; the first pass uses the seeds
    /// `eval --seed S` uses) instead of generated single-object episodes.
    #[arg(long)]
    from_dataset: bool,
    /// Instructions for --from-dataset (JSON Lines with plans) [default: the dev split].
    #[arg(long, value_name = "FILE", requires = "from_dataset")]
    instructions: Option<PathBuf>,
    /// Only this scene (repeatable) [default: every scene].
    #[arg(long)]
    scene: Vec<String>,
    /// Distribution parameters [default: configs/episodes.toml].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Switch every randomised aspect off (the flags below switch one each).
    #[arg(long)]
    no_randomise: bool,
    #[arg(long)]
    no_object_pose: bool,
    #[arg(long)]
    no_colors: bool,
    #[arg(long)]
    no_textures: bool,
    #[arg(long)]
    no_lights: bool,
    #[arg(long)]
    no_background: bool,
    #[arg(long)]
    no_robot_start: bool,
}

pub(crate) fn episodes(args: EpisodesArgs) -> anyhow::Result<()> {
    match args.command {
        EpisodesCommand::Generate(g) => generate(g),
        EpisodesCommand::Show { file } => show(&file),
    }
}

fn params(g: &GenerateArgs) -> anyhow::Result<EpisodeParams> {
    let mut p = match &g.config {
        Some(path) => EpisodeParams::load(path).with_context(|| format!("reading {}", path.display()))?,
        None => EpisodeParams::load_default()?,
    };
    let r = &mut p.randomise;
    for (off, flag) in [
        (g.no_object_pose, &mut r.object_pose),
        (g.no_colors, &mut r.colors),
        (g.no_textures, &mut r.textures),
        (g.no_lights, &mut r.lights),
        (g.no_background, &mut r.background),
        (g.no_robot_start, &mut r.robot_start),
    ] {
        *flag &= !(off || g.no_randomise);
    }
    Ok(p)
}

fn generate(g: GenerateArgs) -> anyhow::Result<()> {
    if g.count == 0 {
        bail!("--count must be at least 1");
    }
    let assets = Assets::load_default()?;
    for s in &g.scene {
        assets.scene(s)?;
    }
    let wanted = |scene: &str| g.scene.is_empty() || g.scene.iter().any(|s| s == scene);
    let p = params(&g)?;
    let mut batch = Vec::with_capacity(g.count);
    if g.from_dataset {
        let path = g
            .instructions
            .clone()
            .unwrap_or_else(|| kitchen_r_core::assets::assets_dir().join("dataset/dev.jsonl"));
        let all: Vec<Instruction> =
            read_jsonl(&path).with_context(|| format!("reading instructions {}", path.display()))?;
        let ins: Vec<Instruction> = all.into_iter().filter(|i| wanted(&i.scene)).collect();
        if ins.is_empty() {
            bail!("no instructions in {} for the scenes asked for", path.display());
        }
        for i in 0..g.count {
            batch.push(from_instruction(
                &assets,
                &p,
                &ins[i % ins.len()],
                g.seed,
                i / ins.len(),
            )?);
            progress(i + 1, g.count);
        }
    } else {
        let scenes: Vec<_> = assets.scenes.iter().filter(|s| wanted(&s.id)).collect();
        for i in 0..g.count {
            let scene = scenes[i % scenes.len()];
            let cfg = generate_varied(scene, &assets.catalogue, &p, g.seed, i as u64)
                .with_context(|| format!("episode {i} in {}", scene.id))?;
            batch.push(cfg);
            progress(i + 1, g.count);
        }
    }
    save_batch(&batch, &g.out)?;
    let r = &p.randomise;
    let on: Vec<&str> = [
        ("object_pose", r.object_pose),
        ("colors", r.colors),
        ("textures", r.textures),
        ("lights", r.lights),
        ("background", r.background),
        ("robot_start", r.robot_start),
    ]
    .into_iter()
    .filter_map(|(k, v)| v.then_some(k))
    .collect();
    println!(
        "wrote {} {} episodes (seed {}) to {}",
        batch.len(),
        if g.from_dataset { "dataset" } else { "generated" },
        g.seed,
        g.out.display()
    );
    println!("{}", counts("scenes", batch.iter().map(|c| c.scene.clone())));
    println!(
        "{}",
        counts("first picked object", batch.iter().map(|c| picked(c).to_string()))
    );
    println!(
        "randomised: {}",
        if on.is_empty() {
            "nothing".into()
        } else {
            on.join(", ")
        }
    );
    Ok(())
}

/// Episode of `ins` in pass `pass` over the instructions: pass 0 draws with the seed `eval`
/// uses for the instruction, later passes with fresh seeds and `#pass` appended to the id.
fn from_instruction(
    assets: &Assets,
    p: &EpisodeParams,
    ins: &Instruction,
    seed: u64,
    pass: usize,
) -> anyhow::Result<EpisodeConfig> {
    let run_seed = match pass {
        0 => seed,
        n => sub_seed(seed, n as u64),
    };
    let s = instruction_seed(run_seed, &ins.id);
    // The aspects switched off above are off in `p`, so `randomise = true` draws only the rest.
    let mut cfg =
        instruction_episode(assets, p, ins, s, true).with_context(|| format!("instruction {}", ins.id))?;
    if pass > 0 {
        cfg.id = format!("{}#{pass}", ins.id);
    }
    Ok(cfg)
}

/// A progress line every 10 % (stderr).
fn progress(done: usize, total: usize) {
    if done == total || done.is_multiple_of((total / 10).max(1)) {
        eprintln!("[{done}/{total}] episodes drawn");
    }
}

fn counts(what: &str, items: impl Iterator<Item = String>) -> String {
    let mut m: BTreeMap<String, usize> = BTreeMap::new();
    for i in items {
        *m.entry(i).or_default() += 1;
    }
    let parts: Vec<String> = m.into_iter().map(|(k, n)| format!("{k} {n}")).collect();
    format!("{what}: {}", parts.join(", "))
}

/// The object the plan picks first.
fn picked(c: &EpisodeConfig) -> &str {
    c.plan
        .iter()
        .find_map(|s| s.strip_prefix("pick the "))
        .unwrap_or("-")
}

fn pattern(p: Option<Pattern>) -> &'static str {
    match p {
        None => "-",
        Some(Pattern::Plain) => "plain",
        Some(Pattern::Tiles { .. }) => "tiles",
        Some(Pattern::Stripes { .. }) => "stripes",
        Some(Pattern::Checker { .. }) => "checker",
        Some(Pattern::Planks { .. }) => "planks",
    }
}

fn show(file: &std::path::Path) -> anyhow::Result<()> {
    let batch = load_batch(file).with_context(|| format!("reading {}", file.display()))?;
    println!(
        "{:<18} {:<10} {:>17} {:>5} {:>3} {:<22} {:<16} {:<9}",
        "id", "scene", "robot start", "steps", "bg", "first picked", "floor/wall", "light"
    );
    for c in &batch {
        let o = c.objects.iter().find(|o| o.name == picked(c));
        let light = c.style.light.as_ref().map_or("sensors".into(), |l| {
            format!(
                "{:.0}° {:.2}",
                l.direction[2].asin().to_degrees(),
                l.ambient + l.diffuse
            )
        });
        println!(
            "{:<18} {:<10} {:>17} {:>5} {:>3} {:<22} {:<16} {:<9}",
            c.id,
            c.scene,
            format!(
                "{:.2},{:.2},{:.2}",
                c.robot_start[0], c.robot_start[1], c.robot_start[2]
            ),
            c.plan.len(),
            c.background.len(),
            o.map_or("-".into(), |o| format!(
                "{} {:.2},{:.2}",
                o.name, o.position[0], o.position[1]
            )),
            format!(
                "{}/{}",
                pattern(c.style.floor_pattern),
                pattern(c.style.wall_pattern)
            ),
            light
        );
    }
    println!("{} episodes", batch.len());
    Ok(())
}
