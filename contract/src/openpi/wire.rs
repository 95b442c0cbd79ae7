//! openpi's msgpack-numpy on the wire (`openpi_client/msgpack_numpy.py` of openpi-client 0.1.2):
//! a numpy array is a msgpack map whose keys are msgpack *binary* strings, `{b"__ndarray__":
//! True, b"data": <raw bytes>, b"dtype": "<f4", b"shape": [..]}`; everything else is plain
//! msgpack. The observation we send is a map with string keys; the reply is read leniently
//! (string or binary keys, extra keys ignored) and strictly where it matters (the action array's
//! dtype, shape and byte count).

use kitchen_r_episode::policy::{ACTION_DIM, HORIZON, PolicyError, PolicyInput, STATE_FIELDS, state_vector};
use rmpv::Value;

use super::keys::KeyMap;
use crate::convert::{CameraPlan, encode_rgb};

/// Deepest nesting read from an endpoint: a reply is a map of arrays, metadata a few levels.
const MAX_DEPTH: usize = 32;

/// A numpy array as msgpack-numpy packs it.
fn ndarray(dtype: &str, shape: &[usize], data: Vec<u8>) -> Value {
    let key = |k: &str| Value::Binary(k.as_bytes().to_vec());
    Value::Map(vec![
        (key("__ndarray__"), Value::Boolean(true)),
        (key("data"), Value::Binary(data)),
        (key("dtype"), Value::String(dtype.into())),
        (
            key("shape"),
            Value::Array(shape.iter().map(|&n| Value::from(n as u64)).collect()),
        ),
    ])
}

/// The cameras of `keys` as the plans the image conversion resizes to (raw RGB, no depth).
pub(crate) fn camera_plans(keys: &KeyMap) -> Vec<CameraPlan> {
    let [height, width] = keys.image_size;
    keys.cameras
        .keys()
        .map(|name| CameraPlan {
            name: name.clone(),
            width,
            height,
            encoding: kitchen_r_proto::policy::v1::ImageEncoding::RawRgb8,
            depth: false,
        })
        .collect()
}

/// The observation of one decision as the key map names it, packed: each camera's image
/// (uint8 `(H, W, 3)`), the standard state vector (float32 `(29,)`), the sub-task sentence.
/// Nothing else: no episode id, scene or step, so the endpoint learns what a gRPC policy does.
pub(crate) fn pack_observation(
    input: &PolicyInput<'_>,
    keys: &KeyMap,
    plans: &[CameraPlan],
) -> Result<Vec<u8>, PolicyError> {
    let o = input.observation;
    let mut map = Vec::with_capacity(plans.len() + 2);
    for plan in plans {
        let img = o.images.iter().find(|i| i.name == plan.name).ok_or_else(|| {
            PolicyError::Call(format!(
                "the simulator rendered no image for camera {:?}",
                plan.name
            ))
        })?;
        let rgb = encode_rgb(img, plan)?.data;
        let shape = [plan.height as usize, plan.width as usize, 3];
        map.push((
            Value::from(keys.cameras[&plan.name].as_str()),
            ndarray("|u1", &shape, rgb),
        ));
    }
    if !keys.state.is_empty() {
        let mut s = Vec::with_capacity(STATE_FIELDS.len());
        state_vector(o, &input.ee_pose, input.previous_action.as_ref(), &mut s);
        let bytes: Vec<u8> = s.iter().flat_map(|&v| (v as f32).to_le_bytes()).collect();
        map.push((
            Value::from(keys.state.as_str()),
            ndarray("<f4", &[s.len()], bytes),
        ));
    }
    if !keys.prompt.is_empty() {
        map.push((Value::from(keys.prompt.as_str()), Value::from(input.sub_task)));
    }
    let mut out = Vec::new();
    rmpv::encode::write_value(&mut out, &Value::Map(map))
        .map_err(|e| PolicyError::Call(format!("packing the observation: {e}")))?;
    Ok(out)
}

/// A message from the endpoint as a msgpack value (bounded depth).
fn read(bytes: &[u8]) -> Result<Value, String> {
    let mut rd = bytes;
    let v = rmpv::decode::read_value_with_max_depth(&mut rd, MAX_DEPTH)
        .map_err(|e| format!("it is not msgpack ({e})"))?;
    if !rd.is_empty() {
        return Err(format!("{} bytes follow the msgpack value", rd.len()));
    }
    Ok(v)
}

/// A map key as text, whether packed as a string or as binary.
fn key_text(k: &Value) -> Option<String> {
    match k {
        Value::String(s) => s.as_str().map(str::to_string),
        Value::Binary(b) => std::str::from_utf8(b).ok().map(str::to_string),
        _ => None,
    }
}

fn get<'a>(map: &'a [(Value, Value)], key: &str) -> Option<&'a Value> {
    map.iter()
        .find(|(k, _)| key_text(k).as_deref() == Some(key))
        .map(|(_, v)| v)
}

/// The server's metadata (sent once on connect): it must be a msgpack map; its keys, for the
/// summary.
pub(crate) fn metadata_keys(bytes: &[u8]) -> Result<Vec<String>, String> {
    match read(bytes)? {
        Value::Map(m) => Ok(m
            .iter()
            .map(|(k, _)| key_text(k).unwrap_or_else(|| k.to_string()))
            .collect()),
        other => Err(format!("it is a msgpack {}, not a map", kind(&other))),
    }
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Nil => "nil",
        Value::Boolean(_) => "boolean",
        Value::Integer(_) | Value::F32(_) | Value::F64(_) => "number",
        Value::String(_) => "string",
        Value::Binary(_) => "binary",
        Value::Array(_) => "array",
        Value::Map(_) => "map",
        Value::Ext(..) => "extension",
    }
}

/// The chunk in a reply: the first 16 rows of its `(H, 10)` float array under `key`, H ≥ 16.
/// Every way a reply can be unusable is a [`PolicyError::BadChunk`] that says what came.
pub(crate) fn unpack_actions(bytes: &[u8], key: &str) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
    let bad = |why: String| PolicyError::BadChunk(format!("openpi reply: {why}"));
    let Value::Map(map) = read(bytes).map_err(bad)? else {
        return Err(bad("it is not a msgpack map".into()));
    };
    let Some(actions) = get(&map, key) else {
        let keys: Vec<String> = map.iter().filter_map(|(k, _)| key_text(k)).collect();
        return Err(bad(format!("no {key:?} key (keys: {keys:?})")));
    };
    let (rows, values) = match actions {
        Value::Map(a) if get(a, "__ndarray__").is_some() => array_values(a).map_err(&bad)?,
        Value::Array(rows) => nested_values(rows).map_err(&bad)?,
        other => {
            return Err(bad(format!(
                "{key:?} is a msgpack {}, not a numpy array",
                kind(other)
            )));
        }
    };
    if rows < HORIZON || values.len() != rows * ACTION_DIM {
        let cols = values.len().checked_div(rows).unwrap_or(0);
        return Err(bad(format!(
            "{key:?} has shape ({rows}, {cols}); it must be (H, {ACTION_DIM}) with H >= {HORIZON} \
             (the first {HORIZON} actions are the chunk)"
        )));
    }
    Ok(values[..HORIZON * ACTION_DIM]
        .chunks_exact(ACTION_DIM)
        .map(|a| a.try_into().unwrap_or([f64::NAN; ACTION_DIM]))
        .collect())
}

/// `(rows, values)` of a msgpack-numpy float array of two dimensions.
fn array_values(a: &[(Value, Value)]) -> Result<(usize, Vec<f64>), String> {
    let dtype = get(a, "dtype").and_then(key_text).unwrap_or_default();
    let shape: Vec<usize> = match get(a, "shape") {
        Some(Value::Array(s)) => s
            .iter()
            .map(|d| d.as_u64().map(|d| d as usize))
            .collect::<Option<_>>()
            .ok_or("the array's shape is not a list of sizes")?,
        _ => return Err("the array has no shape".into()),
    };
    let Some(Value::Binary(data)) = get(a, "data") else {
        return Err("the array has no data bytes".into());
    };
    let &[rows, cols] = shape.as_slice() else {
        return Err(format!(
            "the actions have shape {shape:?}; they must be (H, {ACTION_DIM}) with H >= {HORIZON}"
        ));
    };
    let size = match dtype.as_str() {
        "<f4" => 4,
        "<f8" => 8,
        other => {
            return Err(format!(
                "the actions have dtype {other:?}; they must be float32 or float64"
            ));
        }
    };
    let want = rows.checked_mul(cols).and_then(|n| n.checked_mul(size));
    if want != Some(data.len()) {
        return Err(format!(
            "the array has {} data bytes, its shape ({rows}, {cols}) and dtype {dtype} need {}",
            data.len(),
            want.map_or_else(|| "more".to_string(), |n| n.to_string())
        ));
    }
    let values = if size == 4 {
        data.chunks_exact(4)
            .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
            .collect()
    } else {
        data.chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0xff; 8])))
            .collect()
    };
    // A (rows, cols) array whose cols is not 10 is reported by the caller's shape check.
    Ok((rows, values))
}

/// `(rows, values)` of a plain list of lists of numbers (a policy that answers `.tolist()`).
fn nested_values(rows: &[Value]) -> Result<(usize, Vec<f64>), String> {
    let mut values = Vec::with_capacity(rows.len() * ACTION_DIM);
    for r in rows {
        let Value::Array(r) = r else {
            return Err("the actions are a list, but not a list of lists".into());
        };
        if r.len() != ACTION_DIM {
            return Err(format!(
                "an action has {} values; each must have {ACTION_DIM}",
                r.len()
            ));
        }
        for v in r {
            values.push(v.as_f64().ok_or("an action value is not a number")?);
        }
    }
    Ok((rows.len(), values))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reply(actions: Value) -> Vec<u8> {
        let v = Value::Map(vec![
            (Value::from("actions"), actions),
            (Value::from("server_timing"), Value::Map(vec![])),
        ]);
        let mut out = Vec::new();
        rmpv::encode::write_value(&mut out, &v).unwrap();
        out
    }

    fn f32s(rows: usize, cols: usize) -> Value {
        let data = (0..rows * cols).flat_map(|i| (i as f32).to_le_bytes()).collect();
        ndarray("<f4", &[rows, cols], data)
    }

    #[test]
    fn a_longer_chunk_is_cut_to_the_horizon() {
        let c = unpack_actions(&reply(f32s(50, 10)), "actions").unwrap();
        assert_eq!(c.len(), HORIZON);
        assert_eq!(c[1][2], 12.0);
        let nested = Value::Array(
            (0..16)
                .map(|r| Value::Array((0..10).map(|c| Value::from(f64::from(r * 10 + c))).collect()))
                .collect(),
        );
        assert_eq!(unpack_actions(&reply(nested), "actions").unwrap()[15][9], 159.0);
    }

    #[test]
    fn wrong_replies_say_what_came() {
        let err = |b: &[u8], k: &str| unpack_actions(b, k).unwrap_err().to_string();
        assert!(err(&reply(f32s(8, 10)), "actions").contains("shape (8, 10)"));
        assert!(err(&reply(f32s(16, 7)), "actions").contains("shape (16, 7)"));
        assert!(err(&reply(f32s(16, 10)), "act").contains("no \"act\" key"));
        assert!(err(b"\x92\x01", "actions").contains("not msgpack"));
        assert!(err(b"\x01", "actions").contains("not a msgpack map"));
        let ints = ndarray("<i4", &[16, 10], vec![0; 640]);
        assert!(err(&reply(ints), "actions").contains("dtype \"<i4\""));
        let short = ndarray("<f4", &[16, 10], vec![0; 12]);
        assert!(err(&reply(short), "actions").contains("12 data bytes"));
        assert!(err(&reply(Value::from("x")), "actions").contains("not a numpy array"));
    }

    #[test]
    fn metadata_must_be_a_map() {
        let mut b = Vec::new();
        rmpv::encode::write_value(&mut b, &Value::Map(vec![(Value::from("a"), Value::Nil)])).unwrap();
        assert_eq!(metadata_keys(&b).unwrap(), ["a"]);
        let mut b = Vec::new();
        rmpv::encode::write_value(&mut b, &Value::from(3)).unwrap();
        assert!(metadata_keys(&b).unwrap_err().contains("number, not a map"));
    }
}
