//! `kitchen-r dataset …`: the instruction set's subcommands.
//!
//! - `generate`: regenerate the instruction set deterministically from the scenes, catalogue and
//!   templates (the same seed and phrasings give byte-identical files); with `--phrasings` it
//!   makes a private test set (docs/private-test-set.md).
//! - `audit`: the leak and feasibility audit of a test set (`audit_cmd`, over
//!   `kitchen_r_core::audit`).
//!
//! Each subcommand is one variant of [`DatasetCommand`] and one function below.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand};
use kitchen_r_core::dataset::{self, GenerateOptions, language, templates};

#[path = "audit_cmd.rs"]
mod audit_cmd;

#[derive(Args, Debug)]
pub(crate) struct DatasetArgs {
    #[command(subcommand)]
    command: DatasetCommand,
}

#[derive(Subcommand, Debug)]
enum DatasetCommand {
    /// Write dev.jsonl, test.jsonl, test_ground_truth.jsonl and manifest.json into DIR.
    Generate {
        /// Generator seed (the committed dataset uses 20241; organisers use a secret one).
        #[arg(long)]
        seed: u64,
        /// Output directory, created if missing (keep a private set outside the repository).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Assets directory with scenes/, objects.toml and templates.toml [default: the
        /// KITCHEN_R_ASSETS lookup].
        #[arg(long, value_name = "DIR")]
        assets: Option<PathBuf>,
        /// Private phrasings (templates.toml schema, `id` and `instructions` only) that replace
        /// the public ones in the test split: makes a private set whose manifest records the
        /// file's digest and not the seed.
        #[arg(long, value_name = "FILE")]
        phrasings: Option<PathBuf>,
        /// Language features of the test split: `all`, `none`, or some of relational,pronouns,
        /// implicit,order,distractors (docs/private-test-set.md). Each test instruction is then
        /// composed from the phrase book (assets/language.toml, with the lists of a `[language]`
        /// table in --phrasings replacing its own) and kept only if exactly one plan fits it; the
        /// dev split never changes [default: all with --phrasings, none without].
        #[arg(long, value_name = "LIST", value_parser = language::parse_features)]
        language: Option<BTreeSet<language::Feature>>,
    },
    /// Leak and feasibility audit of a test set: public-phrasing share, the EM of a
    /// template-inversion attack built from public material, test plans shared with dev and,
    /// with --oracle, instructions the oracle cannot complete. Exits non-zero if a check fails.
    Audit(audit_cmd::AuditArgs),
}

pub(crate) fn dataset(args: DatasetArgs) -> anyhow::Result<()> {
    match args.command {
        DatasetCommand::Generate {
            seed,
            out,
            assets,
            phrasings,
            language,
        } => generate(seed, &out, assets, phrasings.as_deref(), language),
        DatasetCommand::Audit(args) => audit_cmd::audit(args),
    }
}

fn generate(
    seed: u64,
    out: &Path,
    assets: Option<PathBuf>,
    phrasings: Option<&Path>,
    language: Option<BTreeSet<language::Feature>>,
) -> anyhow::Result<()> {
    let assets = assets.unwrap_or_else(kitchen_r_core::assets::assets_dir);
    let private = match phrasings {
        Some(path) => {
            let templates = templates::load_templates(&assets.join("templates.toml"))
                .with_context(|| format!("reading the templates under {}", assets.display()))?;
            let private = templates::load_private_phrasings(path, &templates)
                .with_context(|| format!("reading private phrasings {}", path.display()))?;
            Some(private)
        }
        None => None,
    };
    if private.is_some()
        && let Some(repo) = enclosing_git_work_tree(out)
    {
        eprintln!(
            "warning: {} is inside the git work tree {}; keep a private set (its answers and \
             phrasings) out of any repository that is or may be published",
            out.display(),
            repo.display()
        );
    }
    // New language is on by default for private sets only: public samples stay as they were.
    let language = language.unwrap_or_else(|| match private {
        Some(_) => language::Feature::ALL.into_iter().collect(),
        None => BTreeSet::new(),
    });
    let options = GenerateOptions {
        seed,
        private,
        language,
    };
    let ds = dataset::generate_with(&options, &assets)
        .with_context(|| format!("generating from {}", assets.display()))?;
    dataset::write(&ds, out).with_context(|| format!("writing {}", out.display()))?;
    let m = &ds.manifest;
    if let Some(l) = &m.language {
        let features: Vec<&str> = l.features.iter().map(|f| f.as_str()).collect();
        let rejected: Vec<String> = l.rejected.iter().map(|(r, n)| format!("{n} {r}")).collect();
        println!(
            "language ({}): {} test instructions composed, {} kept their template phrasing; \
             renderings refused by the uniqueness checker: {}",
            features.join(", "),
            l.composed,
            l.template_phrased,
            if rejected.is_empty() {
                "none".to_string()
            } else {
                rejected.join(", ")
            }
        );
    }
    match &m.private_phrasings {
        // The seed is a secret of a private set: not echoed into terminals or logs.
        Some(p) => println!(
            "wrote a private set: {} dev and {} test instructions to {} (private phrasings: {} \
             for {} templates, sha256 {})",
            m.dev,
            m.test,
            out.display(),
            p.phrasings,
            p.templates,
            p.sha256
        ),
        None => println!(
            "wrote a public sample: {} dev and {} test instructions (seed {seed}) to {}",
            m.dev,
            m.test,
            out.display()
        ),
    }
    Ok(())
}

/// The nearest ancestor of `path` (made absolute) that holds a `.git`, if any.
fn enclosing_git_work_tree(path: &Path) -> Option<PathBuf> {
    let abs = std::path::absolute(path).ok()?;
    abs.ancestors()
        .find(|dir| dir.join(".git").exists())
        .map(Path::to_path_buf)
}
