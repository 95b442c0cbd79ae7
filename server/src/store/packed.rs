//! How plan files and per-instruction results are stored: zstd-compressed
//! (docs/measured/load-benchmark.md, storage per submission). A 163-line dev plan file shrinks
//! about tenfold; per-instruction results are one compressed JSON array of `[id, present,
//! correct_steps, total_steps]` per run.

use sqlx::FromRow;

use crate::plans::InstructionScore;

/// zstd's default level: fast enough to stay invisible next to scoring, most of the gain.
const LEVEL: i32 = 3;

pub(crate) fn pack(bytes: &[u8]) -> Vec<u8> {
    // Compressing an in-memory buffer only fails on allocation failure.
    zstd::bulk::compress(bytes, LEVEL).expect("zstd compression of an in-memory buffer")
}

pub(crate) fn unpack(blob: &[u8]) -> sqlx::Result<Vec<u8>> {
    zstd::stream::decode_all(blob).map_err(|e| sqlx::Error::Decode(Box::new(e)))
}

/// An episode's path (its plot: docs/reference/pages.md) as compressed JSON.
pub(crate) fn pack_path(path: &kitchen_r_core::topdown::PathPlot) -> Vec<u8> {
    pack(&serde_json::to_vec(path).expect("an episode path serialises"))
}

pub(crate) fn unpack_path(blob: &[u8]) -> sqlx::Result<kitchen_r_core::topdown::PathPlot> {
    serde_json::from_slice(&unpack(blob)?).map_err(|e| sqlx::Error::Decode(Box::new(e)))
}

pub(crate) fn pack_text(text: &str) -> Vec<u8> {
    pack(text.as_bytes())
}

pub(crate) fn unpack_text(blob: &[u8]) -> sqlx::Result<String> {
    String::from_utf8(unpack(blob)?).map_err(|e| sqlx::Error::Decode(Box::new(e)))
}

type Packed = (String, bool, usize, usize);

pub(crate) fn pack_instructions(rows: &[InstructionScore]) -> Vec<u8> {
    let rows: Vec<Packed> = (rows.iter())
        .map(|i| (i.id.clone(), i.present, i.correct, i.total))
        .collect();
    pack(&serde_json::to_vec(&rows).expect("instruction results serialise"))
}

pub(crate) fn unpack_instructions(blob: &[u8]) -> sqlx::Result<Vec<InstructionScore>> {
    let rows: Vec<Packed> =
        serde_json::from_slice(&unpack(blob)?).map_err(|e| sqlx::Error::Decode(Box::new(e)))?;
    Ok(rows
        .into_iter()
        .map(|(id, present, correct, total)| InstructionScore {
            id,
            present,
            correct,
            total,
        })
        .collect())
}

/// A submission's body as stored: compressed in `body_z` (plan files), or as text in `body`
/// (policy submissions' endpoint JSON, which SQL reads with `json_extract`).
#[derive(FromRow)]
pub(crate) struct StoredBody {
    pub split: String,
    pub body: String,
    pub body_z: Option<Vec<u8>>,
}

impl StoredBody {
    pub(crate) fn into_body(self) -> sqlx::Result<super::SubmissionBody> {
        let body = match self.body_z {
            Some(z) => unpack_text(&z)?,
            None => self.body,
        };
        Ok(super::SubmissionBody {
            split: self.split,
            body,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_text_and_instructions_round_trip() {
        let text = "{\"id\": \"dev-0001\", \"plan\": [\"pick(cup)\"]}\n".repeat(50);
        let z = pack_text(&text);
        assert!(z.len() * 5 < text.len(), "{} -> {}", text.len(), z.len());
        assert_eq!(unpack_text(&z).unwrap(), text);
        let rows = vec![
            InstructionScore {
                id: "dev-0001".into(),
                present: true,
                correct: 3,
                total: 4,
            },
            InstructionScore {
                id: "dev-0002".into(),
                present: false,
                correct: 0,
                total: 5,
            },
        ];
        assert_eq!(unpack_instructions(&pack_instructions(&rows)).unwrap(), rows);
        assert!(unpack_text(b"not zstd").is_err());
    }
}
