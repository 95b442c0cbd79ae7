//! The instruction template file (`assets/templates.toml`) and placeholder substitution.
//!
//! A template pairs English phrasings with a plan of step patterns. Placeholders: `{a}`, `{b}`
//! are distinct key objects; `{za}`, `{zb}` the zones those objects start in; `{w}`, `{x}`,
//! `{y}`, `{v}`, `{u}` free, pairwise distinct zone choices. Loading refuses a template whose
//! phrasings do not pin its plan down (a placeholder of the plan missing from a phrasing), so
//! every generated instruction determines its ground truth.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::TEMPLATE_COUNT;
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
