//! The original protocol's client, from the specification's field tables
//! (`shared/reference/legacy-protocol.md`): its own `MsgObject` structs (both dialects), its
//! own framing, PNG decoding with the `png` crate.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use prost::Message;

// ----------------------------------------------------------------------------------------
// The protocol, from the specification's field tables
// ----------------------------------------------------------------------------------------

#[derive(Clone, PartialEq, Message)]
pub struct AgentMovement {
    #[prost(int32, optional, tag = "1")]
    pub action_id: Option<i32>,
    #[prost(float, optional, tag = "2")]
    pub degree: Option<f32>,
    #[prost(float, optional, tag = "3")]
    pub distance: Option<f32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct AgentTurn {
    #[prost(int32, optional, tag = "1")]
    pub action_id: Option<i32>,
    #[prost(float, optional, tag = "2")]
    pub degree: Option<f32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct GridPosition {
    #[prost(float, optional, tag = "1")]
    pub x: Option<f32>,
    #[prost(float, optional, tag = "2")]
    pub y: Option<f32>,
    #[prost(float, optional, tag = "3")]
    pub z: Option<f32>,
    #[prost(float, optional, tag = "4")]
    pub rx: Option<f32>,
    #[prost(float, optional, tag = "5")]
    pub ry: Option<f32>,
    #[prost(float, optional, tag = "6")]
    pub rz: Option<f32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct ActionStatus {
    #[prost(int32, optional, tag = "1")]
    pub action_id: Option<i32>,
    #[prost(int32, optional, tag = "2")]
    pub status: Option<i32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct Images {
    #[prost(bytes = "vec", optional, tag = "1")]
    pub left: Option<Vec<u8>>,
    #[prost(bytes = "vec", optional, tag = "2")]
    pub right: Option<Vec<u8>>,
    #[prost(bytes = "vec", optional, tag = "3")]
    pub main: Option<Vec<u8>>,
}

#[derive(Clone, PartialEq, Message)]
pub struct ResetMsg {
    #[prost(int32, optional, tag = "1")]
    pub reset_type: Option<i32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct Empty {}

#[derive(Clone, PartialEq, Message)]
pub struct VersionCheck {
    #[prost(string, optional, tag = "1")]
    pub version: Option<String>,
}

/// `MsgObject` of the older clients (fields 25–28: HeadMotion, MoveTo, Cancel, Version).
#[derive(Clone, PartialEq, Message)]
pub struct MsgVrnew {
    #[prost(message, optional, tag = "1")]
    pub agent_movement: Option<AgentMovement>,
    #[prost(message, optional, tag = "5")]
    pub grid: Option<GridPosition>,
    #[prost(message, optional, tag = "6")]
    pub status: Option<ActionStatus>,
    #[prost(message, optional, tag = "8")]
    pub images: Option<Images>,
    #[prost(string, optional, tag = "10")]
    pub debug: Option<String>,
    #[prost(message, optional, tag = "11")]
    pub environment_reset: Option<ResetMsg>,
    #[prost(message, optional, tag = "12")]
    pub trial_reset: Option<ResetMsg>,
    #[prost(message, optional, tag = "20")]
    pub start_sync: Option<Empty>,
    #[prost(message, optional, tag = "21")]
    pub stop_sync: Option<Empty>,
    #[prost(message, optional, tag = "23")]
    pub turn: Option<AgentTurn>,
    #[prost(message, optional, tag = "28")]
    pub version: Option<VersionCheck>,
}

/// `MsgObject` of the later client (fields 25–31 renumbered; Images has `mainImage`).
#[derive(Clone, PartialEq, Message)]
pub struct MsgBurkhardt {
    #[prost(message, optional, tag = "1")]
    pub agent_movement: Option<AgentMovement>,
    #[prost(message, optional, tag = "5")]
    pub grid: Option<GridPosition>,
    #[prost(message, optional, tag = "6")]
    pub status: Option<ActionStatus>,
    #[prost(message, optional, tag = "8")]
    pub images: Option<Images>,
    #[prost(string, optional, tag = "10")]
    pub debug: Option<String>,
    #[prost(message, optional, tag = "11")]
    pub environment_reset: Option<ResetMsg>,
    #[prost(message, optional, tag = "12")]
    pub trial_reset: Option<ResetMsg>,
    #[prost(message, optional, tag = "20")]
    pub start_sync: Option<Empty>,
    #[prost(message, optional, tag = "21")]
    pub stop_sync: Option<Empty>,
    #[prost(message, optional, tag = "23")]
    pub turn: Option<AgentTurn>,
    #[prost(message, optional, tag = "29")]
    pub version: Option<VersionCheck>,
}

/// One message, whichever dialect carried it.
#[derive(Debug, Default)]
pub struct Msg {
    pub grid: Option<GridPosition>,
    pub status: Option<ActionStatus>,
    pub images: Option<Images>,
    pub debug: Option<String>,
    pub start_sync: bool,
    pub version: Option<String>,
}

macro_rules! to_msg {
    ($m:expr) => {{
        let m = $m;
        Msg {
            grid: m.grid,
            status: m.status,
            images: m.images,
            debug: m.debug,
            start_sync: m.start_sync.is_some(),
            version: m.version.and_then(|v| v.version),
        }
    }};
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    Vrnew,
    Burkhardt,
}

/// A client of the original protocol: an agent socket (and an environment socket).
pub struct Client {
    pub agent: TcpStream,
    pub env: Option<TcpStream>,
    pub dialect: Dialect,
}

pub const FINISHED: i32 = 1;
pub const ABORTED: i32 = 2;

/// What one cycle brought.
#[derive(Debug, Default)]
pub struct Cycle {
    /// From the Debug trailer ("vrsync cycle N").
    pub number: u64,
    pub statuses: Vec<(i32, i32)>,
    pub images: Option<Images>,
    pub grid: Option<GridPosition>,
}

pub fn connect(port: u16, deadline: Instant) -> TcpStream {
    loop {
        match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => {
                s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
                return s;
            }
            Err(e) => {
                assert!(
                    Instant::now() < deadline,
                    "cannot connect to port {port}: {e}"
                );
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }
}

impl Client {
    /// Connects the environment socket (unless `agent_only`), then agent `id`'s socket,
    /// and passes the version check.
    pub fn start(base: u16, id: u16, dialect: Dialect, agent_only: bool) -> Self {
        let deadline = Instant::now() + Duration::from_secs(30);
        let env = (!agent_only).then(|| connect(base, deadline));
        let agent = connect(base + 1 + id, deadline);
        let mut c = Self {
            agent,
            env,
            dialect,
        };
        let v = VersionCheck {
            version: Some("1.0".into()),
        };
        match dialect {
            Dialect::Vrnew => c.send(&MsgVrnew {
                version: Some(v),
                ..Default::default()
            }),
            Dialect::Burkhardt => c.send(&MsgBurkhardt {
                version: Some(v),
                ..Default::default()
            }),
        }
        let reply = c.next();
        assert_eq!(reply.version.as_deref(), Some("1.0"), "{reply:?}");
        c
    }

    pub fn frame(stream: &mut TcpStream, body: &[u8]) {
        let mut out = (body.len() as i32).to_le_bytes().to_vec();
        out.extend_from_slice(body);
        stream.write_all(&out).unwrap();
    }

    pub fn send(&mut self, msg: &impl Message) {
        Self::frame(&mut self.agent, &msg.encode_to_vec());
    }

    pub fn send_env(&mut self, msg: &MsgVrnew) {
        let env = self.env.as_mut().expect("environment socket");
        Self::frame(env, &msg.encode_to_vec());
    }

    /// The unmodified clients' stop: an empty MsgObject, the frame `00 00 00 00`.
    pub fn stop_zero_length(&mut self) {
        Self::frame(&mut self.agent, &[]);
    }

    /// A real StopSync.
    pub fn stop_sync(&mut self) {
        match self.dialect {
            Dialect::Vrnew => self.send(&MsgVrnew {
                stop_sync: Some(Empty {}),
                ..Default::default()
            }),
            Dialect::Burkhardt => self.send(&MsgBurkhardt {
                stop_sync: Some(Empty {}),
                ..Default::default()
            }),
        }
    }

    pub fn movement(&mut self, id: i32, degree: f32, distance: f32) {
        let m = Some(AgentMovement {
            action_id: Some(id),
            degree: Some(degree),
            distance: Some(distance),
        });
        match self.dialect {
            Dialect::Vrnew => self.send(&MsgVrnew {
                agent_movement: m,
                ..Default::default()
            }),
            Dialect::Burkhardt => self.send(&MsgBurkhardt {
                agent_movement: m,
                ..Default::default()
            }),
        }
    }

    pub fn turn(&mut self, id: i32, degree: f32) {
        let t = Some(AgentTurn {
            action_id: Some(id),
            degree: Some(degree),
        });
        match self.dialect {
            Dialect::Vrnew => self.send(&MsgVrnew {
                turn: t,
                ..Default::default()
            }),
            Dialect::Burkhardt => self.send(&MsgBurkhardt {
                turn: t,
                ..Default::default()
            }),
        }
    }

    /// The next message, or `None` when the host closed the connection.
    pub fn try_next(&mut self) -> Option<Msg> {
        let mut len = [0u8; 4];
        if self.agent.read_exact(&mut len).is_err() {
            return None;
        }
        let len = i32::from_le_bytes(len);
        assert!(len > 0, "the host sent a frame of length {len}");
        let mut body = vec![0; len as usize];
        self.agent.read_exact(&mut body).unwrap();
        Some(match self.dialect {
            Dialect::Vrnew => to_msg!(MsgVrnew::decode(&body[..]).unwrap()),
            Dialect::Burkhardt => to_msg!(MsgBurkhardt::decode(&body[..]).unwrap()),
        })
    }

    pub fn next(&mut self) -> Msg {
        self.try_next().expect("the host closed the connection")
    }

    /// Reads one cycle: everything up to StartSync and the Debug trailer after it.
    /// Statuses that arrive between cycles (acknowledgements) are collected too.
    pub fn cycle(&mut self) -> Option<Cycle> {
        let mut c = Cycle::default();
        let mut started = false;
        loop {
            let m = self.try_next()?;
            if let Some(s) = m.status {
                c.statuses.push((s.action_id.unwrap(), s.status.unwrap()));
            }
            if m.images.is_some() {
                c.images = m.images;
            }
            if m.grid.is_some() {
                c.grid = m.grid;
            }
            started |= m.start_sync;
            if let Some(d) = m.debug
                && started
            {
                c.number = d
                    .strip_prefix("vrsync cycle ")
                    .and_then(|n| n.parse().ok())
                    .unwrap_or_else(|| panic!("unexpected trailer {d:?}"));
                return Some(c);
            }
        }
    }
}

/// Decodes a PNG into `(width, height, colour type, pixels)`.
pub fn decode_png(bytes: &[u8]) -> (u32, u32, png::ColorType, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    (info.width, info.height, info.color_type, buf)
}
