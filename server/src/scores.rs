//! The scores of a run as every answer shows them (submission page, leaderboard).
//!
//! Policy: P is +inf when EM = 0, and JSON has no infinity, so a non-finite score is written as
//! the string `"inf"` (`"-inf"`, `null` for NaN) rather than failing or turning into `null`,
//! which would read as "not scored". Scores that do not apply to a run are left out, except
//! `em`, which the planning track always showed.
//!
//! A leaf module: it imports nothing of this crate, so the store, the leaderboard and the
//! service can all use it without importing each other.

use serde::{Serialize, Serializer};

use kitchen_r_core::scoring::RunScores;
use utoipa::openapi::RefOr;
use utoipa::openapi::schema::{ObjectBuilder, OneOfBuilder, Schema, SchemaType, Type};

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, utoipa::ToSchema)]
pub(crate) struct Scores {
    #[schema(schema_with = score_schema)]
    #[serde(serialize_with = "score")]
    pub em: Option<f64>,
    #[schema(schema_with = score_schema)]
    #[serde(serialize_with = "score", skip_serializing_if = "Option::is_none")]
    pub sr: Option<f64>,
    #[schema(schema_with = score_schema)]
    #[serde(serialize_with = "score", skip_serializing_if = "Option::is_none")]
    pub mse: Option<f64>,
    #[schema(schema_with = score_schema)]
    #[serde(serialize_with = "score", skip_serializing_if = "Option::is_none")]
    pub m: Option<f64>,
    #[schema(schema_with = score_schema)]
    #[serde(serialize_with = "score", skip_serializing_if = "Option::is_none")]
    pub p: Option<f64>,
}

impl Scores {
    /// Planning scores: EM only.
    pub(crate) fn em(em: Option<f64>) -> Scores {
        Scores {
            em,
            ..Scores::default()
        }
    }
}

impl From<RunScores> for Scores {
    fn from(s: RunScores) -> Self {
        Scores {
            em: s.em,
            sr: s.sr,
            mse: s.mse,
            m: s.m,
            p: s.p,
        }
    }
}

/// A number, or `"inf"` / `"-inf"` / `null` when it has no JSON number.
fn score<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    match v {
        Some(x) if x.is_finite() => s.serialize_f64(*x),
        Some(x) if x.is_nan() => s.serialize_none(),
        Some(x) if *x > 0.0 => s.serialize_str("inf"),
        Some(_) => s.serialize_str("-inf"),
        None => s.serialize_none(),
    }
}

/// A score for CSV and HTML: six decimals, `inf` for +inf, empty when absent.
pub(crate) fn fmt_score(v: Option<f64>) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.6}"),
        Some(x) if x.is_nan() => String::new(),
        Some(x) if x > 0.0 => "inf".into(),
        Some(_) => "-inf".into(),
        None => String::new(),
    }
}

/// A score: a number, `null` when it cannot be computed (no episode, NaN), or the strings
/// `inf` / `-inf` (JSON has no infinities).
pub(crate) fn score_schema() -> impl Into<RefOr<Schema>> {
    OneOfBuilder::new()
        .item(ObjectBuilder::new().schema_type(SchemaType::new(Type::Number)))
        .item(ObjectBuilder::new().schema_type(SchemaType::new(Type::Null)))
        .item(
            ObjectBuilder::new()
                .schema_type(SchemaType::new(Type::String))
                .enum_values(Some(["inf", "-inf"])),
        )
        .description(Some(
            "A number; null when it cannot be computed; \"inf\" or \"-inf\" when infinite.",
        ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn infinite_p_is_the_string_inf_and_absent_scores_are_left_out() {
        let s = Scores {
            m: Some(0.5),
            p: Some(f64::INFINITY),
            ..Scores::default()
        };
        assert_eq!(
            serde_json::to_string(&s).unwrap(),
            r#"{"em":null,"m":0.5,"p":"inf"}"#
        );
        assert_eq!(
            serde_json::to_string(&Scores::em(Some(0.25))).unwrap(),
            r#"{"em":0.25}"#
        );
        assert_eq!(fmt_score(Some(f64::INFINITY)), "inf");
        assert_eq!(fmt_score(Some(0.5)), "0.500000");
    }
}
