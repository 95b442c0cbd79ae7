//! Chunk values in JSON: finite numbers as numbers (exact: serde_json's `float_roundtrip`),
//! and the values JSON has no number for as strings (`"NaN"`, `"inf"`, `"-inf"`). A policy may
//! well return them, and the runner's check must refuse them in a replay exactly as it did in
//! the run (its reason does not depend on a NaN's payload, which is therefore not kept).

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::policy::ACTION_DIM;

/// One chunk value as it travels.
#[derive(Debug, Clone, Copy)]
struct Value(f64);

impl Serialize for Value {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let v = self.0;
        match v {
            _ if v.is_finite() => s.serialize_f64(v),
            _ if v.is_nan() => s.serialize_str("NaN"),
            _ if v > 0.0 => s.serialize_str("inf"),
            _ => s.serialize_str("-inf"),
        }
    }
}

struct ValueVisitor;

impl Visitor<'_> for ValueVisitor {
    type Value = Value;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a number, \"NaN\", \"inf\" or \"-inf\"")
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Value, E> {
        Ok(Value(v))
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Value, E> {
        Ok(Value(v as f64))
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Value, E> {
        Ok(Value(v as f64))
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<Value, E> {
        match v {
            "NaN" => Ok(Value(f64::NAN)),
            "inf" => Ok(Value(f64::INFINITY)),
            "-inf" => Ok(Value(f64::NEG_INFINITY)),
            other => Err(E::invalid_value(de::Unexpected::Str(other), &self)),
        }
    }
}

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Value, D::Error> {
        d.deserialize_any(ValueVisitor)
    }
}

/// `#[serde(with = "number::chunk")]` for an optional chunk.
pub(super) mod chunk {
    use super::*;

    type Chunk = Vec<[f64; ACTION_DIM]>;

    pub(crate) fn serialize<S: Serializer>(c: &Option<Chunk>, s: S) -> Result<S::Ok, S::Error> {
        let rows: Option<Vec<[Value; ACTION_DIM]>> =
            c.as_ref().map(|c| c.iter().map(|r| r.map(Value)).collect());
        rows.serialize(s)
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Chunk>, D::Error> {
        let rows = Option::<Vec<[Value; ACTION_DIM]>>::deserialize(d)?;
        Ok(rows.map(|rows| rows.into_iter().map(|r| r.map(|v| v.0)).collect()))
    }
}
