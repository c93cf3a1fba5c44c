//! A Foxglove WebSocket protocol client, for the end-to-end tests and `hvs bench pipeline
//! --view`: written against the protocol's spec (<https://github.com/foxglove/ws-protocol>),
//! not against the server's code (the `foxglove` crate has no client). It connects with the
//! `foxglove.sdk.v1` subprotocol, reads the channel advertisements, subscribes, and reads
//! binary message frames (opcode 1: subscription id u32, log time u64, payload).

use std::collections::BTreeMap;
use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tungstenite::client::IntoClientRequest;
use tungstenite::http::HeaderValue;
use tungstenite::{Message, WebSocket};

/// One advertised channel.
#[derive(Debug, Clone)]
pub struct Advertised {
    /// Channel id.
    pub id: u64,
    /// Topic.
    pub topic: String,
    /// Message encoding (`json`, `protobuf`).
    pub encoding: String,
    /// Schema name.
    pub schema_name: String,
    /// Schema encoding (`jsonschema`, `protobuf`).
    pub schema_encoding: String,
    /// The schema text (a JSON schema, or a base64 protobuf descriptor set).
    pub schema: String,
}

/// A connected client.
pub struct FoxgloveClient {
    ws: WebSocket<TcpStream>,
    /// The server's `serverInfo`.
    pub server_info: Value,
    /// Channels by topic.
    pub channels: BTreeMap<String, Advertised>,
    subscriptions: BTreeMap<u32, String>,
    next_sub: u32,
}

/// One message received.
#[derive(Debug, Clone)]
pub struct Received {
    /// The channel's topic.
    pub topic: String,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// The payload.
    pub payload: Vec<u8>,
}

impl FoxgloveClient {
    /// Connects to `127.0.0.1:port` and waits for the server info and the advertisements.
    pub fn connect(port: u16) -> Result<Self, String> {
        Self::connect_to(std::net::Ipv4Addr::LOCALHOST.into(), port)
    }

    /// Connects to `ip:port` and waits for the server info and the advertisements.
    pub fn connect_to(ip: std::net::IpAddr, port: u16) -> Result<Self, String> {
        let stream = TcpStream::connect((ip, port)).map_err(|e| format!("connect: {e}"))?;
        stream
            .set_read_timeout(Some(Duration::from_millis(200)))
            .map_err(|e| e.to_string())?;
        let mut req = format!("ws://{ip}:{port}/")
            .into_client_request()
            .map_err(|e| e.to_string())?;
        req.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            HeaderValue::from_static("foxglove.sdk.v1"),
        );
        let (ws, resp) = tungstenite::client(req, stream).map_err(|e| format!("handshake: {e}"))?;
        let proto = resp
            .headers()
            .get("sec-websocket-protocol")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("");
        if proto != "foxglove.sdk.v1" {
            return Err(format!("server chose subprotocol {proto:?}"));
        }
        let mut c = Self {
            ws,
            server_info: Value::Null,
            channels: BTreeMap::new(),
            subscriptions: BTreeMap::new(),
            next_sub: 1,
        };
        let deadline = Instant::now() + Duration::from_secs(10);
        while c.server_info.is_null() || c.channels.is_empty() {
            if Instant::now() > deadline {
                return Err("no serverInfo and advertise within 10 s".into());
            }
            c.pump_once()?;
        }
        // Advertisements may come in several messages: take what arrives in the next moment.
        let settle = Instant::now() + Duration::from_millis(300);
        while Instant::now() < settle {
            c.pump_once()?;
        }
        Ok(c)
    }

    /// Reads one frame (or times out quietly); handles text messages, returns binary data.
    fn pump_once(&mut self) -> Result<Option<Received>, String> {
        match self.ws.read() {
            Ok(Message::Text(t)) => {
                let v: Value = serde_json::from_str(t.as_str()).map_err(|e| e.to_string())?;
                match v["op"].as_str() {
                    Some("serverInfo") => self.server_info = v,
                    Some("advertise") => {
                        for ch in v["channels"].as_array().into_iter().flatten() {
                            let a = Advertised {
                                id: ch["id"].as_u64().unwrap_or(0),
                                topic: ch["topic"].as_str().unwrap_or("").into(),
                                encoding: ch["encoding"].as_str().unwrap_or("").into(),
                                schema_name: ch["schemaName"].as_str().unwrap_or("").into(),
                                schema_encoding: ch["schemaEncoding"].as_str().unwrap_or("").into(),
                                schema: ch["schema"].as_str().unwrap_or("").into(),
                            };
                            self.channels.insert(a.topic.clone(), a);
                        }
                    }
                    _ => {}
                }
                Ok(None)
            }
            Ok(Message::Binary(b)) => {
                if b.len() < 13 || b[0] != 1 {
                    return Ok(None);
                }
                let sub = u32::from_le_bytes([b[1], b[2], b[3], b[4]]);
                let mut t = [0u8; 8];
                t.copy_from_slice(&b[5..13]);
                let Some(topic) = self.subscriptions.get(&sub) else {
                    return Ok(None);
                };
                Ok(Some(Received {
                    topic: topic.clone(),
                    log_time_ns: u64::from_le_bytes(t),
                    payload: b[13..].to_vec(),
                }))
            }
            Ok(_) => Ok(None),
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(format!("read: {e}")),
        }
    }

    /// Subscribes to topics (each must be advertised).
    pub fn subscribe(&mut self, topics: &[&str]) -> Result<(), String> {
        let mut subs = Vec::new();
        for t in topics {
            let ch = self
                .channels
                .get(*t)
                .ok_or_else(|| format!("{t} is not advertised"))?;
            let id = self.next_sub;
            self.next_sub += 1;
            subs.push(json!({"id": id, "channelId": ch.id}));
            self.subscriptions.insert(id, (*t).to_string());
        }
        let msg = json!({"op": "subscribe", "subscriptions": subs}).to_string();
        self.ws
            .send(Message::text(msg))
            .map_err(|e| format!("subscribe: {e}"))
    }

    /// Reads for up to about 200 ms: the next message on a subscribed channel, if one came.
    pub fn poll(&mut self) -> Result<Option<Received>, String> {
        self.pump_once()
    }

    /// The next message on a subscribed channel, within `timeout`.
    pub fn next(&mut self, timeout: Duration) -> Result<Received, String> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Some(r) = self.pump_once()? {
                return Ok(r);
            }
        }
        Err(format!("no message within {timeout:?}"))
    }

    /// Collects messages until every topic of `want` has `n` of them, within `timeout`.
    pub fn collect(
        &mut self,
        want: &[&str],
        n: usize,
        timeout: Duration,
    ) -> Result<BTreeMap<String, Vec<Received>>, String> {
        let deadline = Instant::now() + timeout;
        let mut got: BTreeMap<String, Vec<Received>> = BTreeMap::new();
        while want.iter().any(|t| got.get(*t).map_or(0, Vec::len) < n) {
            if Instant::now() > deadline {
                let counts: Vec<String> = want
                    .iter()
                    .map(|t| format!("{t}: {}", got.get(*t).map_or(0, Vec::len)))
                    .collect();
                return Err(format!("within {timeout:?} got only {}", counts.join(", ")));
            }
            if let Some(r) = self.pump_once()? {
                got.entry(r.topic.clone()).or_default().push(r);
            }
        }
        Ok(got)
    }

    /// Sends a text frame as is (for the garbage tests).
    pub fn send_text(&mut self, text: &str) -> Result<(), String> {
        self.ws.send(Message::text(text)).map_err(|e| e.to_string())
    }

    /// Writes the start of a masked text frame that announces 1000 bytes, sends 10 of them,
    /// and closes the connection: a client that goes away in the middle of a message.
    pub fn send_partial_frame_and_drop(mut self) {
        let mut frame = vec![0x81, 0x80 | 126, 0x03, 0xe8, 1, 2, 3, 4];
        frame.extend_from_slice(b"0123456789");
        let _ = std::io::Write::write_all(self.ws.get_mut(), &frame);
        let _ = self.ws.get_mut().shutdown(std::net::Shutdown::Both);
    }

    /// Sends a binary frame as is.
    pub fn send_binary(&mut self, bytes: Vec<u8>) -> Result<(), String> {
        self.ws
            .send(Message::binary(bytes))
            .map_err(|e| e.to_string())
    }
}

/// The `data` field (2) of a protobuf `foxglove.CompressedImage`.
pub fn compressed_image_data(buf: &[u8]) -> Option<&[u8]> {
    bytes_field(buf, 2)
}

/// The first length-delimited field `field` (bytes, string or message) of a protobuf
/// message, read by hand (wire types 0, 1, 2 and 5).
pub fn bytes_field(buf: &[u8], field: u64) -> Option<&[u8]> {
    let mut i = 0usize;
    let varint = |i: &mut usize| -> Option<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *buf.get(*i)?;
            *i += 1;
            v |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Some(v);
            }
        }
        None
    };
    while i < buf.len() {
        let key = varint(&mut i)?;
        match key & 7 {
            0 => {
                varint(&mut i)?;
            }
            1 => i = i.checked_add(8)?,
            5 => i = i.checked_add(4)?,
            2 => {
                let n = usize::try_from(varint(&mut i)?).ok()?;
                let end = i.checked_add(n)?;
                if key >> 3 == field {
                    return buf.get(i..end);
                }
                i = end;
            }
            _ => return None,
        }
    }
    None
}
