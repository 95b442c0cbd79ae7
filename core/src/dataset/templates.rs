//! The instruction template file (`assets/templates.toml`) and placeholder substitution.
//!
//! A template pairs English phrasings with a plan of step patterns. Placeholders: `{a}`, `{b}`
//! are distinct key objects; `{za}`, `{zb}` the zones those objects start in; `{w}`, `{x}`,
//! `{y}`, `{v}`, `{u}` free, pairwise distinct zone choices. Loading refuses a template whose
//! phrasings do not pin its plan down (a placeholder of the plan missing from a phrasing), so
//! every generated instruction determines its ground truth.
//!
//! In a phrasing, a zone written `the {x} zone` may be rendered by the furniture that holds it
//! ([`fill_places`]; the zone's `names` in the scene file), while plan steps always use the colour.
//!
//! A *private phrasings* file ([`load_private_phrasings`]) has the same schema without `plan`:
//! extra phrasings for some templates, kept outside the repository by an organiser, that replace
//! the public ones in the test split of a private test set; its optional `[language]` table
//! replaces lists of the composer's phrase book ([`super::language`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::TEMPLATE_COUNT;
use super::language::Lexicon;
use crate::ContentError;
use crate::plan::Step;

/// Object placeholders, in binding order.
pub const OBJECT_VARS: [&str; 2] = ["a", "b"];
/// Free zone placeholders, in binding order.
pub const FREE_ZONE_VARS: [&str; 5] = ["w", "x", "y", "v", "u"];
/// Plan lengths the paper allows (Language Instructions).
pub const PLAN_LEN: std::ops::RangeInclusive<usize> = 4..=8;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TemplateFile {
    #[serde(rename = "template")]
    templates: Vec<Template>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Template {
    pub id: String,
    /// English phrasings; one is drawn per generated instruction.
    pub instructions: Vec<String>,
    /// Step patterns such as `move to the {za} zone`, `pick the {a}`.
    pub plan: Vec<String>,
}

/// A plan step with a placeholder in place of the zone or object.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Pattern {
    MoveTo(String),
    Pick(String),
    Place(String),
}

/// Placeholder name → substituted text (object name or zone colour).
pub type Binding = BTreeMap<String, String>;

impl Pattern {
    fn parse(s: &str) -> Result<Pattern, String> {
        let var = |inner: &str| {
            inner
                .strip_prefix('{')
                .and_then(|v| v.strip_suffix('}'))
                .filter(|v| !v.contains(['{', '}']))
                .map(str::to_string)
        };
        let p = if let Some(z) = s
            .strip_prefix("move to the ")
            .and_then(|r| r.strip_suffix(" zone"))
        {
            var(z).map(Pattern::MoveTo)
        } else if let Some(o) = s.strip_prefix("pick the ") {
            var(o).map(Pattern::Pick)
        } else if let Some(o) = s.strip_prefix("place the ") {
            var(o).map(Pattern::Place)
        } else {
            None
        };
        let p = p.ok_or_else(|| {
            format!(
                "step pattern {s:?} is not `move to the {{Z}} zone`, `pick the {{O}}` or `place the {{O}}`"
            )
        })?;
        let (name, zone) = match &p {
            Pattern::MoveTo(z) => (z, true),
            Pattern::Pick(o) | Pattern::Place(o) => (o, false),
        };
        if zone != is_zone_var(name) || !is_known(name) {
            return Err(format!(
                "step pattern {s:?}: misplaced or unknown placeholder {{{name}}}"
            ));
        }
        Ok(p)
    }

    /// The canonical step under `binding` (built through [`Step`], never by hand).
    pub fn instantiate(&self, binding: &Binding) -> Option<Step> {
        Some(match self {
            Pattern::MoveTo(z) => Step::MoveTo {
                zone: binding.get(z)?.clone(),
            },
            Pattern::Pick(o) => Step::Pick {
                object: binding.get(o)?.clone(),
            },
            Pattern::Place(o) => Step::Place {
                object: binding.get(o)?.clone(),
            },
        })
    }
}

/// The start-zone placeholder of an object placeholder: `a` → `za`.
pub fn start_zone_var(object: &str) -> String {
    format!("z{object}")
}

fn is_zone_var(name: &str) -> bool {
    FREE_ZONE_VARS.contains(&name) || OBJECT_VARS.iter().any(|o| start_zone_var(o) == name)
}

fn is_known(name: &str) -> bool {
    OBJECT_VARS.contains(&name) || is_zone_var(name)
}

/// Placeholder names in `text`, in order of appearance (with repeats).
pub fn placeholders(text: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        let Some(close) = rest[open..].find('}') else {
            break;
        };
        out.push(&rest[open + 1..open + close]);
        rest = &rest[open + close + 1..];
    }
    out
}

/// Substitute every placeholder of `text`; `None` if one is unbound.
pub fn fill(text: &str, binding: &Binding) -> Option<String> {
    let mut out = String::with_capacity(text.len() + 16);
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        let close = open + rest[open..].find('}')?;
        out.push_str(&rest[..open]);
        out.push_str(binding.get(&rest[open + 1..close])?);
        rest = &rest[close + 1..];
    }
    out.push_str(rest);
    Some(out)
}

/// Like [`fill`], but every `the {Z} zone` (or `The {Z} zone`) with a zone placeholder `Z` is
/// replaced by `place(colour)`, a referring expression with its article ("the blue zone", "the
/// dining table"); it is capitalised where the phrasing had `The`. Other zone mentions, such as
/// `the {x} and {y} zones`, keep the bare colour.
pub fn fill_places(text: &str, binding: &Binding, mut place: impl FnMut(&str) -> String) -> Option<String> {
    let mut out = String::with_capacity(text.len() + 32);
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        let close = open + rest[open..].find('}')?;
        let (before, name, after) = (&rest[..open], &rest[open + 1..close], &rest[close + 1..]);
        let value = binding.get(name)?;
        let article = ["the ", "The "].into_iter().find(|a| {
            before
                .strip_suffix(a)
                .is_some_and(|b| !b.ends_with(|c: char| c.is_alphanumeric()))
        });
        let zone_word = after
            .strip_prefix(" zone")
            .is_some_and(|a| !a.starts_with(|c: char| c.is_alphanumeric()));
        match article {
            Some(article) if zone_word && is_zone_var(name) => {
                out.push_str(&before[..before.len() - article.len()]);
                let phrase = place(value);
                if article == "The " {
                    let mut chars = phrase.chars();
                    if let Some(first) = chars.next() {
                        out.extend(first.to_uppercase());
                        out.push_str(chars.as_str());
                    }
                } else {
                    out.push_str(&phrase);
                }
                rest = &after[" zone".len()..];
            }
            _ => {
                out.push_str(before);
                out.push_str(value);
                rest = after;
            }
        }
    }
    out.push_str(rest);
    Some(out)
}

impl Template {
    pub fn patterns(&self) -> Result<Vec<Pattern>, String> {
        self.plan.iter().map(|s| Pattern::parse(s)).collect()
    }

    /// Object placeholders the template uses (directly or through a start zone), binding order.
    pub fn object_vars(&self) -> Vec<&'static str> {
        let used = self.used();
        OBJECT_VARS
            .into_iter()
            .filter(|o| used.contains(*o) || used.contains(&start_zone_var(o)))
            .collect()
    }

    /// Free zone placeholders the template uses, binding order.
    pub fn free_zone_vars(&self) -> Vec<&'static str> {
        let used = self.used();
        FREE_ZONE_VARS.into_iter().filter(|z| used.contains(*z)).collect()
    }

    fn used(&self) -> BTreeSet<String> {
        let texts = self.plan.iter().chain(&self.instructions);
        texts.flat_map(|t| placeholders(t)).map(str::to_string).collect()
    }

    /// Placeholders a substitution binds: the object placeholders used, their start zones and
    /// the free zone placeholders used.
    pub fn bound_vars(&self) -> BTreeSet<String> {
        let objects = self.object_vars();
        let starts = objects.iter().map(|o| start_zone_var(o));
        let free = self.free_zone_vars();
        let names = objects.iter().chain(&free).map(|v| v.to_string());
        names.chain(starts).collect()
    }

    /// Check the template on its own; the message says what to fix.
    pub fn validate(&self) -> Result<(), String> {
        let ctx = |m: String| format!("template {:?}: {m}", self.id);
        let patterns = self.patterns().map_err(ctx)?;
        if !PLAN_LEN.contains(&patterns.len()) {
            return Err(ctx(format!("plan has {} steps, expected 4 to 8", patterns.len())));
        }
        if self.instructions.is_empty() {
            return Err(ctx("no instruction phrasing".into()));
        }
        let in_plan: BTreeSet<&str> = self.plan.iter().flat_map(|p| placeholders(p)).collect();
        for text in &self.instructions {
            let mentioned: BTreeSet<&str> = placeholders(text).into_iter().collect();
            if let Some(bad) = mentioned.iter().find(|n| !is_known(n)) {
                return Err(ctx(format!("unknown placeholder {{{bad}}} in {text:?}")));
            }
            // Start zones follow from the objects; everything else must be said.
            for var in &in_plan {
                let pinned = match var.strip_prefix('z') {
                    Some(obj) if OBJECT_VARS.contains(&obj) => {
                        mentioned.contains(obj) || mentioned.contains(var)
                    }
                    _ => mentioned.contains(var),
                };
                if !pinned {
                    return Err(ctx(format!(
                        "phrasing {text:?} does not mention {{{var}}} of the plan"
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Read and validate the template file: exactly [`TEMPLATE_COUNT`] templates with unique ids.
pub fn load_templates(path: &Path) -> Result<Vec<Template>, ContentError> {
    let text = std::fs::read_to_string(path).map_err(|source| ContentError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let file: TemplateFile = toml::from_str(&text).map_err(|e| ContentError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let invalid = |message: String| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    if file.templates.len() != TEMPLATE_COUNT {
        return Err(invalid(format!(
            "{} templates, expected exactly {TEMPLATE_COUNT}",
            file.templates.len()
        )));
    }
    let mut ids = BTreeSet::new();
    for t in &file.templates {
        if !ids.insert(&t.id) {
            return Err(invalid(format!("duplicate template id {:?}", t.id)));
        }
        t.validate().map_err(invalid)?;
    }
    Ok(file.templates)
}

/// The private phrasings file: `[[template]]` tables with `id` and `instructions` only.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PrivateFile {
    #[serde(rename = "template", default)]
    templates: Vec<PrivateEntry>,
    /// Lists that replace the public phrase book's ([`super::language::Lexicon::overlay`]).
    #[serde(default)]
    language: Option<Lexicon>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PrivateEntry {
    id: String,
    instructions: Vec<String>,
}

/// Phrasings that replace the public ones in the test split of a private test set, by
/// template id, with the SHA-256 digest of the file they came from. Their text must never be
/// written anywhere public; a manifest records only [`PrivatePhrasings::summary`].
#[derive(Clone, PartialEq, Eq)]
pub struct PrivatePhrasings {
    by_template: BTreeMap<String, Vec<String>>,
    lexicon: Option<Lexicon>,
    sha256: String,
}

/// Shows the summary only, so that logging options never prints a private phrasing.
impl std::fmt::Debug for PrivatePhrasings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = self.summary();
        f.debug_struct("PrivatePhrasings")
            .field("templates", &s.templates)
            .field("phrasings", &s.phrasings)
            .field("sha256", &s.sha256)
            .finish_non_exhaustive()
    }
}

impl PrivatePhrasings {
    /// Parse and check a private phrasings file's text against the (public) templates: every
    /// id names a template, appears once and has at least one phrasing; every phrasing obeys
    /// the template rules (each placeholder of the plan is mentioned), uses only placeholders
    /// the template binds, and is not one of the template's public phrasings.
    pub fn parse(text: &str, templates: &[Template]) -> Result<PrivatePhrasings, String> {
        let file: PrivateFile = toml::from_str(text).map_err(|e| e.to_string())?;
        if file.templates.is_empty() {
            return Err("no [[template]] entries".into());
        }
        if let Some(l) = &file.language {
            l.validate(false).map_err(|m| format!("[language]: {m}"))?;
        }
        let mut by_template = BTreeMap::new();
        for entry in file.templates {
            let ctx = |m: String| format!("private phrasings of template {:?}: {m}", entry.id);
            let Some(public) = templates.iter().find(|t| t.id == entry.id) else {
                return Err(format!(
                    "unknown template id {:?} (ids are those of the templates file, e.g. {:?})",
                    entry.id,
                    templates.first().map_or("t01_move", |t| t.id.as_str())
                ));
            };
            if by_template.contains_key(&entry.id) {
                return Err(ctx("the id appears twice".into()));
            }
            if entry.instructions.is_empty() {
                return Err(ctx("no instruction phrasing".into()));
            }
            let bound = public.bound_vars();
            for text in &entry.instructions {
                if public.instructions.contains(text) {
                    return Err(ctx(format!("{text:?} is also a public phrasing")));
                }
                if let Some(extra) = placeholders(text).into_iter().find(|p| !bound.contains(*p)) {
                    return Err(ctx(format!(
                        "{text:?} uses {{{extra}}}, which the template's plan does not bind"
                    )));
                }
            }
            let check = Template {
                instructions: entry.instructions.clone(),
                ..public.clone()
            };
            check.validate().map_err(|m| format!("private {m}"))?;
            by_template.insert(entry.id, entry.instructions);
        }
        Ok(PrivatePhrasings {
            by_template,
            lexicon: file.language,
            sha256: super::sha256::sha256_hex(text.as_bytes()),
        })
    }

    /// The private phrasings of template `id`, if the file has any.
    pub fn for_template(&self, id: &str) -> Option<&[String]> {
        self.by_template.get(id).map(Vec::as_slice)
    }

    /// The file's `[language]` lists, if it has them.
    pub fn lexicon(&self) -> Option<&Lexicon> {
        self.lexicon.as_ref()
    }

    /// Template ids that have private phrasings, sorted.
    pub fn template_ids(&self) -> impl Iterator<Item = &str> {
        self.by_template.keys().map(String::as_str)
    }

    /// Counts and digest, for the manifest; never the text.
    pub fn summary(&self) -> super::PrivatePhrasingsSummary {
        super::PrivatePhrasingsSummary {
            templates: self.by_template.len(),
            phrasings: self.by_template.values().map(Vec::len).sum(),
            sha256: self.sha256.clone(),
        }
    }
}

/// Read and check a private phrasings file (see [`PrivatePhrasings::parse`]) against the
/// templates it extends.
pub fn load_private_phrasings(path: &Path, templates: &[Template]) -> Result<PrivatePhrasings, ContentError> {
    let text = std::fs::read_to_string(path).map_err(|source| ContentError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    PrivatePhrasings::parse(&text, templates).map_err(|message| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn committed_templates_load() {
        let dir = crate::assets::assets_dir();
        let ts = load_templates(&dir.join("templates.toml")).unwrap();
        let lens: BTreeSet<usize> = ts.iter().map(|t| t.plan.len()).collect();
        assert_eq!(lens, PLAN_LEN.collect(), "every plan length 4..=8 is represented");
    }

    #[test]
    fn fill_and_instantiate() {
        let b: Binding = [("a", "red cup"), ("za", "blue"), ("x", "green")]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        assert_eq!(
            fill("Move the {a} to the {x} zone.", &b).unwrap(),
            "Move the red cup to the green zone."
        );
        assert_eq!(fill("the {b}", &b), None);
        let p = Pattern::parse("move to the {za} zone").unwrap();
        assert_eq!(p.instantiate(&b).unwrap().to_string(), "move to the blue zone");
    }

    #[test]
    fn places_render_by_the_callback_only_in_the_zone_form() {
        let b: Binding = [("a", "bowl"), ("x", "green"), ("y", "red")]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let mut seen = Vec::new();
        let mut furniture = |c: &str| {
            seen.push(c.to_string());
            "the dining table".to_string()
        };
        assert_eq!(
            fill_places(
                "The {x} zone gets the {a}; then the {y} zones.",
                &b,
                &mut furniture
            )
            .unwrap(),
            "The dining table gets the bowl; then the red zones."
        );
        assert_eq!(
            fill_places("Put the {a} on the {x} zone, bathe {y} zone.", &b, &mut furniture).unwrap(),
            "Put the bowl on the dining table, bathe red zone."
        );
        assert_eq!(seen, ["green", "green"]);
        assert_eq!(fill_places("the {b} zone", &b, |_| String::new()), None);
    }

    #[test]
    fn underdetermined_templates_are_refused() {
        let t = Template {
            id: "t".into(),
            instructions: vec!["Move the {a} somewhere.".into()],
            plan: [
                "move to the {za} zone",
                "pick the {a}",
                "move to the {x} zone",
                "place the {a}",
            ]
            .map(String::from)
            .to_vec(),
        };
        assert!(t.validate().unwrap_err().contains("{x}"));
        for bad in [
            "pick the {x}",
            "move to the {a} zone",
            "pick up the {a}",
            "pick the {q}",
        ] {
            assert!(Pattern::parse(bad).is_err(), "{bad}");
        }
    }
}
