//! Phrasings as sequences of literal text and slots, matched against instruction text.
//!
//! A slot is an object (`{a}`), a bare zone colour (`{w}` in "the {w}, {x} and {y} zones") or a
//! zone reference (`the {x} zone`), which an instruction may render either with the colour or
//! with one of the zone's referring expressions (`the dining table`). Matching is anchored at
//! both ends, ASCII case-insensitive, and backtracks over every way a slot could be filled from
//! the scene's vocabulary, so a phrasing matches an instruction exactly when some filling of its
//! slots reproduces the text.

use std::collections::BTreeMap;

use crate::dataset::templates::Binding;
use crate::scene::Scene;

/// One piece of a phrasing.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Token {
    Lit(String),
    /// An object slot: a key object's name (`red cup`).
    Obj(String),
    /// A bare zone colour (`blue`).
    Zone(String),
    /// `the <colour> zone`, or one of that zone's referring expressions.
    ZoneRef(String),
}

/// What a scene offers to fill slots with.
#[derive(Debug, Clone, PartialEq)]
pub struct Vocab {
    /// Key object names with the zone each starts in.
    pub objects: Vec<(String, String)>,
    /// Zone colours with their referring expressions.
    pub zones: Vec<(String, Vec<String>)>,
}

impl Vocab {
    pub fn of(scene: &Scene) -> Vocab {
        Vocab {
            objects: (scene.key_objects.iter())
                .map(|o| (o.name(), o.zone.clone()))
                .collect(),
            zones: (scene.zones.iter())
                .map(|z| (z.color.clone(), z.names.clone()))
                .collect(),
        }
    }

    /// The zone an object starts in.
    pub fn start_zone(&self, object: &str) -> Option<&str> {
        (self.objects.iter())
            .find(|(n, _)| n == object)
            .map(|(_, z)| z.as_str())
    }

    /// Every way a zone reference to `colour` may be written.
    fn zone_refs(&self, colour: &str) -> Vec<String> {
        let names = (self.zones.iter()).find(|(c, _)| c == colour);
        std::iter::once(format!("the {colour} zone"))
            .chain(names.into_iter().flat_map(|(_, n)| n.iter().cloned()))
            .collect()
    }
}

/// Parse a template phrasing (`Move the {a} to the {x} zone.`). `is_object` tells object
/// placeholders from zone ones.
pub fn parse_template(text: &str, is_object: impl Fn(&str) -> bool) -> Vec<Token> {
    let mut tokens = Vec::new();
    let mut lit = String::new();
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        let Some(close) = rest[open..].find('}').map(|c| open + c) else {
            break;
        };
        let var = rest[open + 1..close].to_string();
        lit.push_str(&rest[..open]);
        rest = &rest[close + 1..];
        if is_object(&var) {
            flush(&mut tokens, &mut lit);
            tokens.push(Token::Obj(var));
            continue;
        }
        let after = rest.strip_prefix(" zone").filter(|r| !starts_alnum(r));
        match (strip_suffix_ci(&lit, "the "), after) {
            (Some(head), Some(after)) if !ends_alnum(head) => {
                lit.truncate(head.len());
                flush(&mut tokens, &mut lit);
                tokens.push(Token::ZoneRef(var));
                rest = after;
            }
            _ => {
                flush(&mut tokens, &mut lit);
                tokens.push(Token::Zone(var));
            }
        }
    }
    lit.push_str(rest);
    flush(&mut tokens, &mut lit);
    tokens
}

/// An instruction with every object and zone mention replaced by a slot: objects `o1`, `o2`,
/// zones `q1`, `q2`, … numbered in order of first mention.
#[derive(Debug, Clone, PartialEq)]
pub struct Abstracted {
    pub tokens: Vec<Token>,
    /// Slot → object name or zone colour.
    pub binding: Binding,
}

/// Replace the mentions in `text` by slots (longest mention first at each word start).
pub fn abstract_text(text: &str, vocab: &Vocab) -> Abstracted {
    let mut candidates: Vec<(String, Token, String)> = Vec::new();
    for (name, _) in &vocab.objects {
        candidates.push((name.clone(), Token::Obj(String::new()), name.clone()));
    }
    for (colour, _) in &vocab.zones {
        for r in vocab.zone_refs(colour) {
            candidates.push((r, Token::ZoneRef(String::new()), colour.clone()));
        }
        candidates.push((colour.clone(), Token::Zone(String::new()), colour.clone()));
    }
    let mut tokens = Vec::new();
    let mut lit = String::new();
    let mut slots: BTreeMap<(bool, String), String> = BTreeMap::new();
    let mut binding = Binding::new();
    let mut pos = 0;
    while pos < text.len() {
        let rest = &text[pos..];
        let at_word = pos == 0 || !ends_alnum(&text[..pos]);
        let best = (candidates.iter())
            .filter(|(s, _, _)| at_word && mention_at(rest, s))
            .max_by_key(|(s, _, _)| s.len());
        if let Some((s, kind, value)) = best {
            let is_obj = matches!(kind, Token::Obj(_));
            let count = slots.keys().filter(|(o, _)| *o == is_obj).count() + 1;
            let var = (slots.entry((is_obj, value.clone())))
                .or_insert_with(|| format!("{}{count}", if is_obj { 'o' } else { 'q' }))
                .clone();
            binding.insert(var.clone(), value.clone());
            flush(&mut tokens, &mut lit);
            tokens.push(match kind {
                Token::Obj(_) => Token::Obj(var),
                Token::ZoneRef(_) => Token::ZoneRef(var),
                _ => Token::Zone(var),
            });
            pos += s.len();
        } else {
            let c = rest.chars().next().unwrap_or(' ');
            lit.push(c);
            pos += c.len_utf8();
        }
    }
    flush(&mut tokens, &mut lit);
    Abstracted { tokens, binding }
}

/// Whether `text` starts with the mention `s`, ending at a word boundary.
fn mention_at(text: &str, s: &str) -> bool {
    starts_with_ci(text, s) && !starts_alnum(&text[s.len()..])
}

/// Call `accept` with each binding under which `tokens` reproduce `text`, until it returns true;
/// returns whether it did. Distinct object slots take distinct objects; slots for which
/// `distinct_zone` holds take pairwise distinct zones.
pub fn matches(
    tokens: &[Token],
    text: &str,
    vocab: &Vocab,
    distinct_zone: &dyn Fn(&str) -> bool,
    accept: &mut dyn FnMut(&Binding) -> bool,
) -> bool {
    let mut m = Matcher {
        tokens,
        text,
        vocab,
        distinct_zone,
        accept,
        binding: Binding::new(),
    };
    m.go(0, 0)
}

struct Matcher<'a> {
    tokens: &'a [Token],
    text: &'a str,
    vocab: &'a Vocab,
    distinct_zone: &'a dyn Fn(&str) -> bool,
    accept: &'a mut dyn FnMut(&Binding) -> bool,
    binding: Binding,
}

impl Matcher<'_> {
    fn go(&mut self, k: usize, pos: usize) -> bool {
        let Some(token) = self.tokens.get(k) else {
            return pos == self.text.len() && (self.accept)(&self.binding);
        };
        let rest = &self.text[pos..];
        let (var, options): (&String, Vec<(String, String)>) = match token {
            Token::Lit(s) => return starts_with_ci(rest, s) && self.go(k + 1, pos + s.len()),
            Token::Obj(v) => (
                v,
                (self.vocab.objects.iter())
                    .map(|(n, _)| (n.clone(), n.clone()))
                    .collect(),
            ),
            Token::Zone(v) => (
                v,
                (self.vocab.zones.iter())
                    .map(|(c, _)| (c.clone(), c.clone()))
                    .collect(),
            ),
            Token::ZoneRef(v) => (
                v,
                (self.vocab.zones.iter())
                    .flat_map(|(c, _)| self.vocab.zone_refs(c).into_iter().map(|r| (r, c.clone())))
                    .collect(),
            ),
        };
        let is_obj = matches!(token, Token::Obj(_));
        let bound = self.binding.get(var).cloned();
        for (written, value) in options {
            if !mention_at(rest, &written) {
                continue;
            }
            match &bound {
                Some(b) if *b != value => continue,
                Some(_) => {
                    if self.go(k + 1, pos + written.len()) {
                        return true;
                    }
                    continue;
                }
                None => {}
            }
            if self.clashes(var, &value, is_obj) {
                continue;
            }
            self.binding.insert(var.clone(), value);
            if self.go(k + 1, pos + written.len()) {
                return true;
            }
            self.binding.remove(var);
        }
        false
    }

    /// Whether giving `value` to the new slot `var` breaks distinctness.
    fn clashes(&self, var: &str, value: &str, is_obj: bool) -> bool {
        let kind_of = |v: &str| {
            self.tokens.iter().find_map(|t| match t {
                Token::Obj(x) if x == v => Some(true),
                Token::Zone(x) | Token::ZoneRef(x) if x == v => Some(false),
                _ => None,
            })
        };
        let distinct = |v: &str| is_obj || (self.distinct_zone)(v);
        distinct(var)
            && (self.binding.iter()).any(|(v, val)| {
                val == value && kind_of(v) == Some(is_obj) && (is_obj || (self.distinct_zone)(v))
            })
    }
}

fn flush(tokens: &mut Vec<Token>, lit: &mut String) {
    if !lit.is_empty() {
        tokens.push(Token::Lit(std::mem::take(lit)));
    }
}

fn starts_with_ci(text: &str, prefix: &str) -> bool {
    text.len() >= prefix.len()
        && text.is_char_boundary(prefix.len())
        && text.as_bytes()[..prefix.len()].eq_ignore_ascii_case(prefix.as_bytes())
}

fn strip_suffix_ci<'a>(text: &'a str, suffix: &str) -> Option<&'a str> {
    let cut = text.len().checked_sub(suffix.len())?;
    (text.is_char_boundary(cut) && text.as_bytes()[cut..].eq_ignore_ascii_case(suffix.as_bytes()))
        .then(|| &text[..cut])
}

fn starts_alnum(s: &str) -> bool {
    s.chars().next().is_some_and(char::is_alphanumeric)
}

fn ends_alnum(s: &str) -> bool {
    s.chars().next_back().is_some_and(char::is_alphanumeric)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vocab() -> Vocab {
        Vocab {
            objects: vec![
                ("red cup".into(), "blue".into()),
                ("cup".into(), "red".into()),
                ("bowl".into(), "red".into()),
            ],
            zones: vec![
                (
                    "blue".into(),
                    vec!["the shelf".into(), "the shelf by the fridge".into()],
                ),
                ("red".into(), vec!["the dining table".into()]),
                ("green".into(), vec![]),
            ],
        }
    }

    fn is_obj(v: &str) -> bool {
        v == "a" || v == "b"
    }

    fn all(tokens: &[Token], text: &str) -> Vec<Binding> {
        let mut out = Vec::new();
        matches(tokens, text, &vocab(), &|v| v != "za", &mut |b| {
            out.push(b.clone());
            false
        });
        out
    }

    #[test]
    fn template_phrasings_split_into_slots() {
        let t = parse_template(
            "The {x} zone has the {a}; visit the {w}, {y} and {v} zones.",
            is_obj,
        );
        assert_eq!(
            t,
            vec![
                Token::ZoneRef("x".into()),
                Token::Lit(" has the ".into()),
                Token::Obj("a".into()),
                Token::Lit("; visit the ".into()),
                Token::Zone("w".into()),
                Token::Lit(", ".into()),
                Token::Zone("y".into()),
                Token::Lit(" and ".into()),
                Token::Zone("v".into()),
                Token::Lit(" zones.".into()),
            ]
        );
    }

    #[test]
    fn zone_references_match_colour_or_furniture() {
        let t = parse_template("Move the {a} to the {x} zone.", is_obj);
        for (text, x) in [
            ("Move the red cup to the green zone.", "green"),
            ("Move the red cup to the dining table.", "red"),
            ("move the red cup to the shelf by the fridge.", "blue"),
            ("Move the red cup to the shelf.", "blue"),
        ] {
            let found = all(&t, text);
            assert_eq!(found.len(), 1, "{text}");
            assert_eq!(found[0]["x"], x);
            assert_eq!(found[0]["a"], "red cup");
        }
        assert!(all(&t, "Move the red cup to the green zone, then go.").is_empty());
        assert!(all(&t, "Move the plate to the green zone.").is_empty());
    }

    #[test]
    fn distinct_slots_take_distinct_values() {
        let t = parse_template("Swap the {a} and the {b}.", is_obj);
        assert!(all(&t, "Swap the cup and the cup.").is_empty());
        let t = parse_template("Go to the {w} zone and the {x} zone.", is_obj);
        assert!(all(&t, "Go to the blue zone and the shelf.").is_empty());
        assert_eq!(all(&t, "Go to the blue zone and the dining table.").len(), 1);
    }

    #[test]
    fn abstraction_numbers_mentions_in_order() {
        let a = abstract_text(
            "Put the red cup on the dining table, then the cup in the red zone and the blue one.",
            &vocab(),
        );
        assert_eq!(a.binding["o1"], "red cup");
        assert_eq!(a.binding["o2"], "cup");
        assert_eq!(a.binding["q1"], "red");
        assert_eq!(a.binding["q2"], "blue");
        let zone_refs = a
            .tokens
            .iter()
            .filter(|t| **t == Token::ZoneRef("q1".into()))
            .count();
        assert_eq!(zone_refs, 2, "{:?}", a.tokens);
    }
}
