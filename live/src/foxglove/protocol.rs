//! The part of the Foxglove WebSocket protocol (v1) a live view needs: the server's JSON
//! messages (`serverInfo`, `advertise`), the binary `messageData` and `time` frames, and the
//! client's `subscribe` / `unsubscribe`. Every other client operation is ignored, as the
//! protocol allows for capabilities a server does not announce.

use serde::Deserialize;
use serde_json::json;

/// Subprotocols the server accepts: Lichtblick and older Foxglove clients offer the first,
/// current Foxglove the second; their v1 messages are the same.
pub(crate) const SUBPROTOCOLS: [&str; 2] = ["foxglove.websocket.v1", "foxglove.sdk.v1"];

/// Binary opcodes, server to client.
const MESSAGE_DATA: u8 = 0x01;
const TIME: u8 = 0x02;

/// One advertised topic.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Channel {
    pub id: u32,
    pub topic: String,
    /// `pkg/msg/Name`.
    pub schema_name: String,
    /// The `ros2msg` text with its dependencies.
    pub schema: String,
}

/// `serverInfo`: the first message on every connection. The `time` capability makes the
/// client's clock follow the episode's sim time (sent as `time` frames).
pub(crate) fn server_info(name: &str, session_id: &str) -> String {
    json!({
        "op": "serverInfo",
        "name": name,
        "capabilities": ["time"],
        "supportedEncodings": [],
        "metadata": {},
        "sessionId": session_id,
    })
    .to_string()
}

/// `advertise`: CDR messages with `ros2msg` schemas, as in the MCAP recordings.
pub(crate) fn advertise(channels: &[Channel]) -> String {
    let list: Vec<_> = channels
        .iter()
        .map(|c| {
            json!({
                "id": c.id,
                "topic": c.topic,
                "encoding": "cdr",
                "schemaName": c.schema_name,
                "schema": c.schema,
                "schemaEncoding": "ros2msg",
            })
        })
        .collect();
    json!({ "op": "advertise", "channels": list }).to_string()
}

/// `messageData`: opcode, subscription id, log time (ns), the CDR payload.
pub(crate) fn message_data(subscription: u32, log_time_ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut b = Vec::with_capacity(13 + payload.len());
    b.push(MESSAGE_DATA);
    b.extend_from_slice(&subscription.to_le_bytes());
    b.extend_from_slice(&log_time_ns.to_le_bytes());
    b.extend_from_slice(payload);
    b
}

/// `time`: the server's clock (the episode's sim time, ns).
pub(crate) fn time(ns: u64) -> Vec<u8> {
    let mut b = Vec::with_capacity(9);
    b.push(TIME);
    b.extend_from_slice(&ns.to_le_bytes());
    b
}

#[derive(Debug, Deserialize, PartialEq)]
pub(crate) struct Subscription {
    pub id: u32,
    #[serde(rename = "channelId")]
    pub channel_id: u32,
}

/// The client operations the server acts on.
#[derive(Debug, Deserialize, PartialEq)]
#[serde(tag = "op")]
pub(crate) enum ClientOp {
    #[serde(rename = "subscribe")]
    Subscribe { subscriptions: Vec<Subscription> },
    #[serde(rename = "unsubscribe")]
    Unsubscribe {
        #[serde(rename = "subscriptionIds")]
        subscription_ids: Vec<u32>,
    },
}

/// A client's text message: `None` for operations this server does not offer, or garbage.
pub(crate) fn parse(text: &str) -> Option<ClientOp> {
    serde_json::from_str(text).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn client_operations_parse_and_unknown_ones_are_ignored() {
        let s = r#"{"op":"subscribe","subscriptions":[{"id":3,"channelId":7}]}"#;
        let want = vec![Subscription { id: 3, channel_id: 7 }];
        assert_eq!(parse(s), Some(ClientOp::Subscribe { subscriptions: want }));
        let u = r#"{"op":"unsubscribe","subscriptionIds":[3]}"#;
        let want = ClientOp::Unsubscribe {
            subscription_ids: vec![3],
        };
        assert_eq!(parse(u), Some(want));
        assert_eq!(parse(r#"{"op":"getParameters","parameterNames":[]}"#), None);
        assert_eq!(parse("not json"), None);
    }

    #[test]
    fn binary_frames_are_little_endian_after_their_opcode() {
        let m = message_data(0x0102_0304, 5, b"xy");
        assert_eq!(m, [1, 4, 3, 2, 1, 5, 0, 0, 0, 0, 0, 0, 0, b'x', b'y']);
        assert_eq!(time(1), [2, 1, 0, 0, 0, 0, 0, 0, 0]);
    }
}
