//! The dataset's Parquet files, with the column names and Arrow types LeRobot's own writer
//! produces (`datasets` features → Arrow; `pandas.to_parquet` for the tasks): Snappy, one row
//! group per episode in the data files.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use arrow_array::builder::{Float64Builder, Int64Builder, ListBuilder, StringBuilder};
use arrow_array::{
    ArrayRef, FixedSizeListArray, Float32Array, Float64Array, Int64Array, RecordBatch, StringArray,
};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::WriterProperties;

use super::episode::Column;
use super::stats::FeatureStats;
use super::{LeRobotError, io_err};

/// One episode's rows in a data file.
pub(crate) struct DataRows<'a> {
    pub columns: &'a [Column],
    pub episode_index: i64,
    /// The global `index` of its first frame.
    pub first_index: i64,
    /// Global task index of each frame.
    pub task_index: Vec<i64>,
}

/// One row of `meta/episodes/chunk-*/file-*.parquet`.
pub(crate) struct EpisodeRow {
    pub episode_index: i64,
    pub tasks: Vec<String>,
    pub length: i64,
    /// `(chunk, file)` of its data rows (and, the same, of its videos and this row).
    pub file: (i64, i64),
    pub dataset_from_index: i64,
    pub dataset_to_index: i64,
    /// Its span in every camera's video file, seconds.
    pub from_timestamp: f64,
    pub to_timestamp: f64,
    /// `(feature key, statistics)`, the same keys in the same order for every row.
    pub stats: Vec<(String, FeatureStats)>,
    pub instruction: String,
    pub scene: String,
    /// The collection's name for it (`ep00012`), shared with its MCAP/HDF5 files.
    pub source: String,
}

fn write_parquet(path: &Path, schema: Arc<Schema>, batches: &[RecordBatch]) -> Result<(), LeRobotError> {
    let file = std::fs::File::create(path).map_err(io_err(path))?;
    let props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    let mut w = ArrowWriter::try_new(file, schema, Some(props))?;
    for b in batches {
        w.write(b)?;
        // One row group per batch: LeRobot reads an episode with `read_row_group(i)`.
        w.flush()?;
    }
    w.close()?;
    Ok(())
}

fn vector_type(dim: usize) -> DataType {
    DataType::FixedSizeList(Arc::new(Field::new("item", DataType::Float32, true)), dim as i32)
}

/// `data/chunk-*/file-*.parquet`: the numeric features, then `timestamp` (seconds from the
/// episode's start), `frame_index`, `episode_index`, `index` and `task_index`.
pub(crate) fn write_data(path: &Path, episodes: &[DataRows<'_>], fps: u32) -> Result<(), LeRobotError> {
    let Some(first) = episodes.first() else {
        return Ok(());
    };
    let mut fields: Vec<Field> = first
        .columns
        .iter()
        .map(|c| Field::new(&c.key, vector_type(c.names.len()), false))
        .collect();
    fields.push(Field::new("timestamp", DataType::Float32, false));
    for k in ["frame_index", "episode_index", "index", "task_index"] {
        fields.push(Field::new(k, DataType::Int64, false));
    }
    let schema = Arc::new(Schema::new(fields));
    let mut batches = Vec::with_capacity(episodes.len());
    for e in episodes {
        let n = e.task_index.len();
        let mut arrays: Vec<ArrayRef> = Vec::new();
        for c in e.columns {
            let item = Arc::new(Field::new("item", DataType::Float32, true));
            let values = Arc::new(Float32Array::from(c.values.clone()));
            arrays.push(Arc::new(FixedSizeListArray::try_new(
                item,
                c.names.len() as i32,
                values,
                None,
            )?));
        }
        let frames = 0..n as i64;
        arrays.push(Arc::new(Float32Array::from_iter_values(
            frames.clone().map(|k| k as f32 / fps as f32),
        )));
        arrays.push(Arc::new(Int64Array::from_iter_values(frames.clone())));
        arrays.push(Arc::new(Int64Array::from(vec![e.episode_index; n])));
        arrays.push(Arc::new(Int64Array::from_iter_values(
            frames.map(|k| e.first_index + k),
        )));
        arrays.push(Arc::new(Int64Array::from(e.task_index.clone())));
        batches.push(RecordBatch::try_new(schema.clone(), arrays)?);
    }
    write_parquet(path, schema, &batches)
}

/// `meta/tasks.parquet` as `pandas.DataFrame({"task_index": ...}, index=Index(tasks,
/// name="task")).to_parquet()` writes it: LeRobot reads it with `pd.read_parquet` and looks a
/// task up by the index (`tasks.iloc[task_index].name`), so the pandas metadata that makes
/// `task` the index is required, not decoration.
pub(crate) fn write_tasks(path: &Path, tasks: &[String]) -> Result<(), LeRobotError> {
    let pandas = serde_json::json!({
        "index_columns": ["task"],
        "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode",
                            "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": null}
        ],
        "creator": {"library": "kitchen-r", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.2.3"
    });
    let schema = Arc::new(Schema::new_with_metadata(
        vec![
            Field::new("task_index", DataType::Int64, false),
            Field::new("task", DataType::Utf8, false),
        ],
        HashMap::from([("pandas".to_string(), pandas.to_string())]),
    ));
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(Int64Array::from_iter_values(0..tasks.len() as i64)),
            Arc::new(StringArray::from_iter_values(tasks)),
        ],
    )?;
    write_parquet(path, schema, &[batch])
}

/// Appends `(name, array)` columns.
#[derive(Default)]
struct Columns {
    fields: Vec<Field>,
    arrays: Vec<ArrayRef>,
}

impl Columns {
    fn push(&mut self, name: &str, array: ArrayRef) {
        self.fields
            .push(Field::new(name, array.data_type().clone(), true));
        self.arrays.push(array);
    }

    fn int(&mut self, name: &str, rows: &[EpisodeRow], f: impl Fn(&EpisodeRow) -> i64) {
        self.push(name, Arc::new(Int64Array::from_iter_values(rows.iter().map(f))));
    }

    fn float(&mut self, name: &str, rows: &[EpisodeRow], f: impl Fn(&EpisodeRow) -> f64) {
        self.push(name, Arc::new(Float64Array::from_iter_values(rows.iter().map(f))));
    }

    fn string(&mut self, name: &str, rows: &[EpisodeRow], f: impl Fn(&EpisodeRow) -> &str) {
        self.push(name, Arc::new(StringArray::from_iter_values(rows.iter().map(f))));
    }
}

/// `meta/episodes/chunk-*/file-*.parquet`, the columns of LeRobot's `save_episode` in its
/// order (`episode_index`, `tasks`, `length`, the data and video locations, `stats/<feature>/
/// <stat>`, `meta/episodes/...`), then ours (`instruction`, `scene`, `source`).
pub(crate) fn write_episodes(
    path: &Path,
    rows: &[EpisodeRow],
    video_keys: &[String],
) -> Result<(), LeRobotError> {
    let Some(first) = rows.first() else {
        return Ok(());
    };
    let mut c = Columns::default();
    c.int("episode_index", rows, |r| r.episode_index);
    let mut tasks = ListBuilder::new(StringBuilder::new());
    for r in rows {
        tasks.append_value(r.tasks.iter().map(Some));
    }
    c.push("tasks", Arc::new(tasks.finish()));
    c.int("length", rows, |r| r.length);
    c.int("data/chunk_index", rows, |r| r.file.0);
    c.int("data/file_index", rows, |r| r.file.1);
    c.int("dataset_from_index", rows, |r| r.dataset_from_index);
    c.int("dataset_to_index", rows, |r| r.dataset_to_index);
    for key in video_keys {
        c.int(&format!("videos/{key}/chunk_index"), rows, |r| r.file.0);
        c.int(&format!("videos/{key}/file_index"), rows, |r| r.file.1);
        c.float(&format!("videos/{key}/from_timestamp"), rows, |r| {
            r.from_timestamp
        });
        c.float(&format!("videos/{key}/to_timestamp"), rows, |r| r.to_timestamp);
    }
    for (fi, (key, s)) in first.stats.iter().enumerate() {
        for (si, (stat, _)) in s.entries().iter().enumerate() {
            let array: ArrayRef = if s.image {
                image_stat_column(rows, fi, si)
            } else {
                let mut b = ListBuilder::new(Float64Builder::new());
                for r in rows {
                    b.append_value(r.stats[fi].1.entries()[si].1.iter().map(|x| Some(*x)));
                }
                Arc::new(b.finish())
            };
            c.push(&format!("stats/{key}/{stat}"), array);
        }
        let mut count = ListBuilder::new(Int64Builder::new());
        for r in rows {
            count.append_value([Some(r.stats[fi].1.count as i64)]);
        }
        c.push(&format!("stats/{key}/count"), Arc::new(count.finish()));
    }
    c.int("meta/episodes/chunk_index", rows, |r| r.file.0);
    c.int("meta/episodes/file_index", rows, |r| r.file.1);
    c.string("instruction", rows, |r| &r.instruction);
    c.string("scene", rows, |r| &r.scene);
    c.string("source", rows, |r| &r.source);
    let schema = Arc::new(Schema::new(c.fields));
    let batch = RecordBatch::try_new(schema.clone(), c.arrays)?;
    write_parquet(path, schema, &[batch])
}

/// An image statistic of shape (C, 1, 1): a list of lists of one-element lists.
fn image_stat_column(rows: &[EpisodeRow], feature: usize, stat: usize) -> ArrayRef {
    let mut b = ListBuilder::new(ListBuilder::new(ListBuilder::new(Float64Builder::new())));
    for r in rows {
        let values = &r.stats[feature].1.entries()[stat].1;
        for v in values {
            let channel = b.values();
            channel.values().append_value([Some(*v)]);
            channel.append(true);
        }
        b.append(true);
    }
    Arc::new(b.finish())
}
