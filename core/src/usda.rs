//! A reader for the subset of USD ASCII (`.usda`) that Kitchen-R scenes use: the `#usda 1.0`
//! header and layer metadata, `def Type "name" (metadata) { … }` prims nested to any depth, and
//! attributes (`[custom] [uniform] type[[]] name = value`) whose values are numbers, strings,
//! tokens, tuples and lists of those. Not a general USD implementation: no composition (`over`,
//! `class`, references, payloads, variants), no time samples, no relationships' targets (skipped),
//! no `.usdc` binary files. Errors name the line, so a malformed file says where to fix it.

use std::collections::BTreeMap;

/// An attribute or metadata value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Number(f64),
    Str(String),
    /// A bare word: `true`, `None`, a token written without quotes.
    Word(String),
    Tuple(Vec<Value>),
    List(Vec<Value>),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Attr {
    /// Declared type (`double3`, `color3f[]`, `token`).
    pub ty: String,
    /// `None` for a declaration without a value.
    pub value: Option<Value>,
    pub line: usize,
}

#[derive(Debug, Clone, PartialEq, Default)]
pub struct Prim {
    /// Schema type (`Xform`, `Cube`); empty for a typeless `def`.
    pub kind: String,
    pub name: String,
    pub line: usize,
    /// Prim metadata in parentheses (`apiSchemas` with its list-edit keyword dropped).
    pub meta: BTreeMap<String, Value>,
    pub attrs: BTreeMap<String, Attr>,
    pub children: Vec<Prim>,
}

/// A parsed layer: its metadata and root prims.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Layer {
    pub meta: BTreeMap<String, Value>,
    pub prims: Vec<Prim>,
}

impl Layer {
    /// The `defaultPrim`, else the first root prim.
    pub fn default_prim(&self) -> Option<&Prim> {
        match self.meta.get("defaultPrim") {
            Some(Value::Str(name)) => self.prims.iter().find(|p| &p.name == name),
            _ => self.prims.first(),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Word(String),
    Str(String),
    Punct(char),
}

/// `line N: message`.
fn at(line: usize, message: impl std::fmt::Display) -> String {
    format!("line {line}: {message}")
}

fn tokenize(text: &str) -> Result<Vec<(Tok, usize)>, String> {
    let mut toks = Vec::new();
    let mut chars = text.chars().peekable();
    let mut line = 1;
    while let Some(c) = chars.next() {
        match c {
            '\n' => line += 1,
            c if c.is_whitespace() => {}
            '#' => {
                while chars.peek().is_some_and(|c| *c != '\n') {
                    chars.next();
                }
            }
            '"' | '\'' => {
                let start = line;
                let mut s = String::new();
                loop {
                    match chars.next() {
                        None => return Err(at(start, "string never closed")),
                        Some('\n') => return Err(at(start, "string runs past the end of the line")),
                        Some('\\') => match chars.next() {
                            Some('n') => s.push('\n'),
                            Some('t') => s.push('\t'),
                            Some(e) => s.push(e),
                            None => return Err(at(start, "string never closed")),
                        },
                        Some(q) if q == c => break,
                        Some(ch) => s.push(ch),
                    }
                }
                toks.push((Tok::Str(s), start));
            }
            '(' | ')' | '[' | ']' | '{' | '}' | '=' | ',' | ';' | '<' | '>' | '@' => {
                toks.push((Tok::Punct(c), line));
            }
            c if c.is_alphanumeric() || "_:.-+/".contains(c) => {
                let mut w = String::from(c);
                while let Some(&n) = chars.peek() {
                    if n.is_alphanumeric() || "_:.-+/".contains(n) {
                        w.push(n);
                        chars.next();
                    } else {
                        break;
                    }
                }
                toks.push((Tok::Word(w), line));
            }
            c => return Err(at(line, format!("unexpected character {c:?}"))),
        }
    }
    Ok(toks)
}

struct Parser {
    toks: Vec<(Tok, usize)>,
    pos: usize,
    last_line: usize,
}

impl Parser {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos).map(|(t, _)| t)
    }

    fn line(&self) -> usize {
        self.toks.get(self.pos).map_or(self.last_line, |(_, l)| *l)
    }

    fn next(&mut self, what: &str) -> Result<Tok, String> {
        let line = self.line();
        let (t, _) = self
            .toks
            .get(self.pos)
            .cloned()
            .ok_or_else(|| at(line, format!("file ends where {what} was expected")))?;
        self.pos += 1;
        Ok(t)
    }

    fn is(&self, c: char) -> bool {
        self.peek() == Some(&Tok::Punct(c))
    }

    fn expect(&mut self, c: char) -> Result<(), String> {
        let line = self.line();
        match self.next(&format!("'{c}'"))? {
            Tok::Punct(p) if p == c => Ok(()),
            t => Err(at(line, format!("expected '{c}', found {}", show(&t)))),
        }
    }

    fn value(&mut self) -> Result<Value, String> {
        let line = self.line();
        match self.next("a value")? {
            Tok::Str(s) => Ok(Value::Str(s)),
            Tok::Word(w) => Ok(w.parse::<f64>().map_or(Value::Word(w), Value::Number)),
            Tok::Punct(open @ ('(' | '[')) => {
                let close = if open == '(' { ')' } else { ']' };
                let mut items = Vec::new();
                while !self.is(close) {
                    items.push(self.value()?);
                    if !self.is(close) {
                        self.expect(',')?;
                    }
                }
                self.expect(close)?;
                Ok(if open == '(' {
                    Value::Tuple(items)
                } else {
                    Value::List(items)
                })
            }
            Tok::Punct('@') => Err(at(line, "asset paths (@…@) are not read: inline the geometry")),
            t => Err(at(line, format!("expected a value, found {}", show(&t)))),
        }
    }

    /// `( key = value … )`; list edits (`prepend apiSchemas = […]`) keep the key only.
    fn metadata(&mut self) -> Result<BTreeMap<String, Value>, String> {
        let mut meta = BTreeMap::new();
        self.expect('(')?;
        while !self.is(')') {
            let line = self.line();
            let mut key = match self.next("a metadata key")? {
                Tok::Word(w) => w,
                // A layer's doc string may stand alone.
                Tok::Str(s) => {
                    meta.insert("doc".into(), Value::Str(s));
                    continue;
                }
                t => return Err(at(line, format!("expected a metadata key, found {}", show(&t)))),
            };
            if matches!(key.as_str(), "prepend" | "append" | "add" | "delete" | "reorder") {
                key = match self.next("a metadata key")? {
                    Tok::Word(w) => w,
                    t => return Err(at(line, format!("expected a metadata key, found {}", show(&t)))),
                };
            }
            self.expect('=')?;
            let v = self.value()?;
            meta.insert(key, v);
            if self.is(';') {
                self.pos += 1;
            }
        }
        self.expect(')')?;
        Ok(meta)
    }

    fn prim(&mut self) -> Result<Prim, String> {
        let line = self.line();
        match self.next("'def'")? {
            Tok::Word(w) if w == "def" => {}
            Tok::Word(w) if w == "over" || w == "class" => {
                return Err(at(
                    line,
                    format!("'{w}' (composition) is not read: write every prim with 'def'"),
                ));
            }
            t => return Err(at(line, format!("expected 'def', found {}", show(&t)))),
        }
        let mut prim = Prim {
            line,
            ..Prim::default()
        };
        match self.next("a prim type or name")? {
            Tok::Word(kind) => {
                prim.kind = kind;
                match self.next("the prim's name")? {
                    Tok::Str(name) => prim.name = name,
                    t => {
                        return Err(at(
                            line,
                            format!("expected the prim's quoted name, found {}", show(&t)),
                        ));
                    }
                }
            }
            Tok::Str(name) => prim.name = name,
            t => {
                return Err(at(
                    line,
                    format!("expected a prim type or name, found {}", show(&t)),
                ));
            }
        }
        if self.is('(') {
            prim.meta = self.metadata()?;
        }
        self.expect('{')?;
        while !self.is('}') {
            if self.peek().is_none() {
                return Err(at(
                    line,
                    format!("prim \"{}\" is never closed with '}}'", prim.name),
                ));
            }
            if matches!(self.peek(), Some(Tok::Word(w)) if w == "def" || w == "over" || w == "class") {
                prim.children.push(self.prim()?);
            } else {
                self.property(&mut prim)?;
            }
        }
        self.expect('}')?;
        Ok(prim)
    }

    /// One attribute (or a relationship, skipped) into `prim`.
    fn property(&mut self, prim: &mut Prim) -> Result<(), String> {
        let line = self.line();
        let mut words = Vec::new();
        loop {
            match self.next("an attribute")? {
                Tok::Word(w) => words.push(w),
                Tok::Punct('[') => {
                    self.expect(']')?;
                    if let Some(ty) = words.last_mut() {
                        ty.push_str("[]");
                    }
                }
                t => return Err(at(line, format!("expected an attribute, found {}", show(&t)))),
            }
            if self.is('=') || self.is('(') || self.is('}') || self.line() != line {
                break;
            }
        }
        words.retain(|w| !matches!(w.as_str(), "custom" | "uniform" | "varying"));
        if words.first().is_some_and(|w| w == "rel") {
            // Relationships (material bindings, …) carry nothing the twin uses.
            if self.is('=') {
                self.pos += 1;
                self.skip_value()?;
            }
            return Ok(());
        }
        let [ty, name] = <[String; 2]>::try_from(words).map_err(|w| {
            at(
                line,
                format!("expected 'type name = value', found {}", w.join(" ")),
            )
        })?;
        if name.ends_with(".timeSamples") || name.ends_with(".connect") {
            return Err(at(
                line,
                format!("{name}: time samples and connections are not read"),
            ));
        }
        let value = if self.is('=') {
            self.pos += 1;
            Some(self.value()?)
        } else {
            None
        };
        if self.is('(') {
            self.metadata()?;
        }
        prim.attrs.insert(name, Attr { ty, value, line });
        Ok(())
    }

    fn skip_value(&mut self) -> Result<(), String> {
        if self.is('<') {
            while !self.is('>') {
                self.next("'>'")?;
            }
            self.pos += 1;
            Ok(())
        } else {
            self.value().map(|_| ())
        }
    }
}

fn show(t: &Tok) -> String {
    match t {
        Tok::Word(w) => format!("'{w}'"),
        Tok::Str(s) => format!("\"{s}\""),
        Tok::Punct(c) => format!("'{c}'"),
    }
}

/// Parse `.usda` text; the error names the line.
pub fn parse(text: &str) -> Result<Layer, String> {
    let first = text.lines().next().unwrap_or_default();
    if !first.starts_with("#usda 1.0") {
        return Err(at(1, "not USD ASCII: the file must start with '#usda 1.0'"));
    }
    let toks = tokenize(text)?;
    let last_line = text.lines().count().max(1);
    let mut p = Parser {
        toks,
        pos: 0,
        last_line,
    };
    let mut layer = Layer::default();
    if p.is('(') {
        layer.meta = p.metadata()?;
    }
    while p.peek().is_some() {
        layer.prims.push(p.prim()?);
    }
    Ok(layer)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"#usda 1.0
(
    defaultPrim = "k"
    metersPerUnit = 0.01
    upAxis = "Z"
)

def Xform "k"
{
    custom string kitchenr:name = "a \"quoted\" name" # a comment
    def Cube "box" (
        prepend apiSchemas = ["PhysicsCollisionAPI"]
    )
    {
        double size = 2
        double3 xformOp:translate = (1, -2.5, 3e-1)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        color3f[] primvars:displayColor = [(0.5, 0.25, 1)]
        rel material:binding = </k/Looks/Red>
        float3[] extent
    }
}
"#;

    #[test]
    fn reads_prims_attributes_and_metadata() {
        let layer = parse(SMALL).unwrap();
        assert_eq!(layer.meta["metersPerUnit"], Value::Number(0.01));
        let k = layer.default_prim().unwrap();
        assert_eq!((k.kind.as_str(), k.line), ("Xform", 8));
        assert_eq!(
            k.attrs["kitchenr:name"].value,
            Some(Value::Str("a \"quoted\" name".into()))
        );
        let b = &k.children[0];
        assert_eq!(
            b.meta["apiSchemas"],
            Value::List(vec![Value::Str("PhysicsCollisionAPI".into())])
        );
        let t = &b.attrs["xformOp:translate"];
        assert_eq!(t.ty, "double3");
        assert_eq!(
            t.value,
            Some(Value::Tuple(vec![
                Value::Number(1.0),
                Value::Number(-2.5),
                Value::Number(0.3)
            ]))
        );
        assert_eq!(b.attrs["primvars:displayColor"].ty, "color3f[]");
        assert_eq!(b.attrs["extent"].value, None);
        assert!(!b.attrs.contains_key("material:binding"));
    }

    #[test]
    fn errors_name_the_line() {
        for (text, want) in [
            (
                "#usda 1.0\ndef Xform \"a\"\n{\n    double x = (1, 2\n}\n",
                "line 5: expected ','",
            ),
            (
                "#usda 1.0\nover \"a\" {}\n",
                "line 2: 'over' (composition) is not read",
            ),
            (
                "#usda 1.0\ndef Xform \"a\" {\n  string s = \"open\n}\n",
                "line 3: string runs past",
            ),
            (
                "#usda 1.0\ndef Xform \"a\" {\n\n  double x = 1\n",
                "line 2: prim \"a\" is never closed",
            ),
            (
                "#usda 1.0\ndef Xform \"a\" {\n  double3 xformOp:translate.timeSamples = {}\n}\n",
                "line 3: xformOp:translate.timeSamples",
            ),
            ("PXR-USDC", "line 1: not USD ASCII"),
        ] {
            let err = parse(text).unwrap_err();
            assert!(err.starts_with(want), "{text:?}: {err}");
        }
    }

    proptest::proptest! {
        /// Whatever follows the header, the reader answers Ok or an error, never a panic.
        #[test]
        fn never_panics(body in "[ -~\\n]{0,200}") {
            let _ = parse(&format!("#usda 1.0\n{body}"));
        }

        #[test]
        fn never_panics_on_near_usda(cut in 0usize..700) {
            let end = SMALL.char_indices().map(|(i, _)| i).take_while(|i| *i <= cut).last().unwrap_or(0);
            let _ = parse(&SMALL[..end]);
        }
    }
}
