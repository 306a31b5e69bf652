//! A client's messages into the session: a TRANSFORM (or POSITION) whose device name is a
//! scene tool's name becomes [`Inbound::Pose`]; anything else becomes [`Inbound::Bad`]
//! with the reason, and the session answers the client with an error (a STRING, see
//! [`super::outbound`]). Checked in this order: the body's length and CRC-64, version 2's
//! extended header, the type (TRANSFORM or POSITION), the device name (a tool of the
//! scene), the content (its length, finite values, a rigid rotation within 1e-3 or a unit
//! quaternion within 1e-3).

use std::time::Instant;

use super::error::Error;
use super::header::HeaderRepr;
use super::message::open_body;
use super::position::PositionRepr;
use super::transform::TransformRepr;
use crate::live::engine::Pose;
use crate::live::hub::{ClientId, Inbound};

/// The message types a client may send.
pub const TAKEN: [&str; 2] = ["TRANSFORM", "POSITION"];

/// The session's event for a message (`header` and its whole `body`) from `client`;
/// `tools` are the scene's tool names.
pub fn inbound_of(
    client: ClientId,
    header: &HeaderRepr,
    body: &[u8],
    tools: &[String],
    received: Instant,
) -> Inbound {
    match pose_of(header, body, tools) {
        Ok(pose) => Inbound::Pose {
            client,
            tool: header.device.clone(),
            pose,
            received,
        },
        Err(why) => Inbound::Bad {
            client,
            message: format!(
                "OpenIGTLink {} from device {:?} refused: {why}",
                header.type_name, header.device
            ),
        },
    }
}

/// Why a message is refused, in words.
#[derive(Debug)]
enum Refusal {
    Codec(Error),
    UnknownTool { tools: Vec<String> },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::Codec(e) => write!(f, "{e}"),
            Refusal::UnknownTool { tools } => write!(
                f,
                "no tool of the scene has this name (the device name must be one of {tools:?})"
            ),
        }
    }
}

impl From<Error> for Refusal {
    fn from(e: Error) -> Self {
        Refusal::Codec(e)
    }
}

fn pose_of(header: &HeaderRepr, body: &[u8], tools: &[String]) -> Result<Pose, Refusal> {
    let parts = open_body(header, body)?;
    if !TAKEN.contains(&header.type_name.as_str()) {
        return Err(Error::UnknownType(header.type_name.clone()).into());
    }
    if !tools.contains(&header.device) {
        return Err(Refusal::UnknownTool {
            tools: tools.to_vec(),
        });
    }
    Ok(match header.type_name.as_str() {
        "TRANSFORM" => TransformRepr::parse_bytes(parts.content)?.pose()?,
        _ => PositionRepr::parse_bytes(parts.content)?.pose()?,
    })
}
