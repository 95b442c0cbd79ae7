//! The composer's phrase book (`assets/language.toml`, or a private `[language]` table) and the
//! language features it can switch.
//!
//! Every entry is a list of patterns with named holes: `{obj}` an object reference ("the red
//! cup", "the cup next to the bowl", "it"), `{place}` a place reference ("the blue zone", "the
//! dining table", "where the bowl is"), `{variant}` a colour word, `{a}` and `{b}` two runs of
//! clauses (order words). A private phrasings file may carry a `[language]` table with any of
//! these lists; each list it names replaces the public one, so a private set can be composed from
//! wording no public file contains.

use std::collections::BTreeSet;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::ContentError;

/// One switchable feature of the composed language.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Feature {
    /// "the cup on the dining table", "the cup next to the bowl", "the other cup", "the apple"
    /// for the only apple, and places named by what is there ("where the bowl is").
    Relational,
    /// "pick up the apple and put it on the shelf": "it" for an object said just before.
    Pronouns,
    /// One verb for a pick and its place ("put the mug in the sink": the moves are implied)
    /// and "bring me the fork", with a sentence saying where "me" is.
    Implicit,
    /// Clauses reordered by order words: "before you …", "…, but first …", "after you …".
    Order,
    /// Words that add no step: "leave the plate where it is", "the red cup, not the blue one".
    Distractors,
}

impl Feature {
    pub const ALL: [Feature; 5] = [
        Feature::Relational,
        Feature::Pronouns,
        Feature::Implicit,
        Feature::Order,
        Feature::Distractors,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Feature::Relational => "relational",
            Feature::Pronouns => "pronouns",
            Feature::Implicit => "implicit",
            Feature::Order => "order",
            Feature::Distractors => "distractors",
        }
    }
}

impl std::fmt::Display for Feature {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Parse a feature list: `all`, `none`, or names separated by commas (`relational,order`).
pub fn parse_features(text: &str) -> Result<BTreeSet<Feature>, String> {
    match text.trim() {
        "all" => return Ok(Feature::ALL.into_iter().collect()),
        "none" | "" => return Ok(BTreeSet::new()),
        _ => {}
    }
    text.split(',')
        .map(|name| {
            let name = name.trim();
            (Feature::ALL.into_iter().find(|f| f.as_str() == name)).ok_or_else(|| {
                let known: Vec<&str> = Feature::ALL.iter().map(|f| f.as_str()).collect();
                format!(
                    "unknown language feature {name:?} (expected all, none or some of {})",
                    known.join(", ")
                )
            })
        })
        .collect()
}

/// The phrase book. Empty lists in a private `[language]` table are not allowed; lists it does
/// not name keep the public wording ([`Lexicon::overlay`]).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Lexicon {
    /// Go to a place: `{place}`.
    pub go: Vec<String>,
    /// Go to the speaker: no hole ("come back to me").
    pub go_me: Vec<String>,
    /// Go to a place holding something, without putting it down: `{obj}`, `{place}`.
    pub go_holding: Vec<String>,
    /// Pick an object up: `{obj}`.
    pub pick: Vec<String>,
    /// Put the held object down: `{obj}`, `{place}`.
    pub place: Vec<String>,
    /// Pick and place in one verb (implicit moves): `{obj}`, `{place}`.
    pub put: Vec<String>,
    /// Pick and place at the speaker: `{obj}`.
    pub bring_me: Vec<String>,
    /// Where the speaker is: `{place}`.
    pub me_at: Vec<String>,
    /// Joins two clauses in the order they are done: the text between them (", then ").
    pub then: Vec<String>,
    /// Order words, said in the order done: `{a}` first, `{b}` after ("after you {a}, {b}").
    pub after: Vec<String>,
    /// Order words, said in reverse: `{b}` said first, done second ("before you {b}, {a}").
    pub before: Vec<String>,
    /// An object on a place: `{obj}` (a bare noun phrase, "the cup"), `{place}`.
    pub on: Vec<String>,
    /// An object next to another: `{obj}` (bare), `{other}` the other object.
    pub next_to: Vec<String>,
    /// The second of two objects of a kind: `{noun}` ("cup").
    pub other: Vec<String>,
    /// A place named by an object there: `{obj}`.
    pub by: Vec<String>,
    /// A contrast that adds no step: `{obj}` (the meant one), `{variant}` (the other's colour).
    pub contrast: Vec<String>,
    /// A sentence that adds no step: `{obj}`.
    pub leave: Vec<String>,
    /// The pronoun for an object said just before.
    pub it: Vec<String>,
}

/// Lists and the holes each pattern of the list must have.
const HOLES: [(&str, &[&str]); 18] = [
    ("go", &["{place}"]),
    ("go_me", &[]),
    ("go_holding", &["{obj}", "{place}"]),
    ("pick", &["{obj}"]),
    ("place", &["{obj}", "{place}"]),
    ("put", &["{obj}", "{place}"]),
    ("bring_me", &["{obj}"]),
    ("me_at", &["{place}"]),
    ("then", &[]),
    ("after", &["{a}", "{b}"]),
    ("before", &["{a}", "{b}"]),
    ("on", &["{obj}", "{place}"]),
    ("next_to", &["{obj}", "{other}"]),
    ("other", &["{noun}"]),
    ("by", &["{obj}"]),
    ("contrast", &["{obj}", "{variant}"]),
    ("leave", &["{obj}"]),
    ("it", &[]),
];

impl Lexicon {
    fn lists(&self) -> [&Vec<String>; 18] {
        [
            &self.go,
            &self.go_me,
            &self.go_holding,
            &self.pick,
            &self.place,
            &self.put,
            &self.bring_me,
            &self.me_at,
            &self.then,
            &self.after,
            &self.before,
            &self.on,
            &self.next_to,
            &self.other,
            &self.by,
            &self.contrast,
            &self.leave,
            &self.it,
        ]
    }

    fn lists_mut(&mut self) -> [&mut Vec<String>; 18] {
        [
            &mut self.go,
            &mut self.go_me,
            &mut self.go_holding,
            &mut self.pick,
            &mut self.place,
            &mut self.put,
            &mut self.bring_me,
            &mut self.me_at,
            &mut self.then,
            &mut self.after,
            &mut self.before,
            &mut self.on,
            &mut self.next_to,
            &mut self.other,
            &mut self.by,
            &mut self.contrast,
            &mut self.leave,
            &mut self.it,
        ]
    }

    /// Every pattern has its list's holes and no others. With `complete`, every list has a
    /// pattern (the public phrase book); otherwise a list is absent or non-empty (a private
    /// table cannot name a list and leave it empty: serde cannot tell, so it reads as absent).
    pub fn validate(&self, complete: bool) -> Result<(), String> {
        for ((name, holes), list) in HOLES.iter().zip(self.lists()) {
            if complete && list.is_empty() {
                return Err(format!("language list `{name}` is empty"));
            }
            for p in list {
                if let Some(missing) = holes.iter().find(|h| !p.contains(**h)) {
                    return Err(format!("language `{name}` pattern {p:?} lacks {missing}"));
                }
                if p.matches('{').count() != holes.len() {
                    return Err(format!(
                        "language `{name}` pattern {p:?} has holes other than {}",
                        if holes.is_empty() {
                            "none".to_string()
                        } else {
                            holes.join(", ")
                        }
                    ));
                }
            }
        }
        // Mentions are numbered in the order said, so these lists fix which hole comes first.
        let first = |name: &str, list: &[String], a: &str, b: &str| {
            let bad = list.iter().find(|p| p.find(a) > p.find(b));
            bad.map_or(Ok(()), |p| {
                Err(format!("language `{name}` pattern {p:?} must say {a} before {b}"))
            })
        };
        first("after", &self.after, "{a}", "{b}")?;
        first("before", &self.before, "{b}", "{a}")?;
        first("on", &self.on, "{obj}", "{place}")?;
        first("next_to", &self.next_to, "{obj}", "{other}")?;
        first("contrast", &self.contrast, "{obj}", "{variant}")?;
        Ok(())
    }

    /// This phrase book with every list `private` names replaced by the private one.
    pub fn overlay(&self, private: &Lexicon) -> Lexicon {
        let mut out = self.clone();
        for (mine, theirs) in out.lists_mut().into_iter().zip(private.lists()) {
            if !theirs.is_empty() {
                mine.clone_from(theirs);
            }
        }
        out
    }

    /// Patterns in all, for summaries.
    pub fn len(&self) -> usize {
        self.lists().iter().map(|l| l.len()).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Read and check the public phrase book (`assets/language.toml`).
pub fn load_lexicon(path: &Path) -> Result<Lexicon, ContentError> {
    let text = std::fs::read_to_string(path).map_err(|source| ContentError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let lexicon: Lexicon = toml::from_str(&text).map_err(|e| ContentError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    lexicon.validate(true).map_err(|message| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    })?;
    Ok(lexicon)
}
