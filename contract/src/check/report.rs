//! The conformance report: one verdict per check, in the order the checks ran.

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Pass,
    Fail,
    Skip,
}

/// One line of the report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Check {
    pub name: &'static str,
    pub verdict: Verdict,
    pub detail: String,
}

impl std::fmt::Display for Check {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = match self.verdict {
            Verdict::Pass => "PASS",
            Verdict::Fail => "FAIL",
            Verdict::Skip => "SKIP",
        };
        write!(f, "{v}  {:<12} {}", self.name, self.detail)
    }
}

/// Every check in order, with its verdict.
#[derive(Debug, Clone, Default)]
pub struct Report {
    pub checks: Vec<Check>,
}

impl Report {
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.verdict != Verdict::Fail)
    }

    /// The named check, if it ran.
    pub fn get(&self, name: &str) -> Option<&Check> {
        self.checks.iter().find(|c| c.name == name)
    }

    /// Add `name`'s verdict: PASS with the detail, or FAIL with the reason; whether it passed.
    pub(crate) fn push(&mut self, name: &'static str, r: Result<String, String>) -> bool {
        let ok = r.is_ok();
        let (verdict, detail) = match r {
            Ok(d) => (Verdict::Pass, d),
            Err(d) => (Verdict::Fail, d),
        };
        self.checks.push(Check {
            name,
            verdict,
            detail,
        });
        ok
    }

    /// Report every check of `names` SKIP: it cannot be judged `because`.
    pub(crate) fn skip(&mut self, names: &[&'static str], because: &str) {
        for name in names {
            self.checks.push(Check {
                name,
                verdict: Verdict::Skip,
                detail: format!("not run: {because}"),
            });
        }
    }
}
