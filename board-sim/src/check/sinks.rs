//! What the host and the graphics engine make of the packets they took: the surface frames
//! and per-step tool forces (the run's outputs), and the evidence of a fault on the way
//! (damaged packets, and packets the boards sent that never arrived).

use std::collections::BTreeMap;
use std::sync::Mutex;

use anyhow::{anyhow, bail, Result};
use link_proto::packet::{ADDR_GRAPHICS, ADDR_HOST};
use link_proto::payload::{surface_entry, SurfaceHeader, ToolForcePayload};
use link_proto::{Machine, PacketKind, PacketRepr};
use pe_firmware::runtime::{Fault, FaultKind, Op};

use super::observed::{phase, Observed};
use crate::fabric::{packet_header, GlobalNet};
use crate::results::{BoardResult, GraphicsFrame};

/// The sinks' packets turned into frames and per-step tool forces (summed in board order).
pub fn collect_sinks(
    net: &GlobalNet,
    steps: u64,
    tools: usize,
) -> Result<(Vec<GraphicsFrame>, Vec<[f64; 3]>)> {
    let graphics = net.graphics.lock().map(|v| v.clone()).unwrap_or_default();
    let host = net.host.lock().map(|v| v.clone()).unwrap_or_default();
    Ok((
        graphics_frames(&graphics)?,
        tool_forces(&host, steps, tools)?,
    ))
}

/// The surface frames the graphics engine assembled from the boards' chunks.
fn graphics_frames(graphics: &[Vec<u8>]) -> Result<Vec<GraphicsFrame>> {
    let mut frames: BTreeMap<u32, GraphicsFrame> = Default::default();
    for p in graphics {
        let r =
            PacketRepr::parse_bytes(p).map_err(|e| anyhow!("graphics engine: bad packet: {e}"))?;
        let h = SurfaceHeader::parse(r.payload)
            .map_err(|e| anyhow!("graphics engine: bad surface payload from {}: {e}", r.src))?;
        let f = frames.entry(h.frame).or_insert_with(|| GraphicsFrame {
            frame: h.frame,
            steps: (h.step, h.step),
            nodes: Vec::new(),
            packets: 0,
        });
        f.steps = (f.steps.0.min(h.step), f.steps.1.max(h.step));
        f.packets += 1;
        for k in 0..h.count as usize {
            f.nodes.push(
                surface_entry(r.payload, k)
                    .map_err(|e| anyhow!("graphics engine: bad surface entry: {e}"))?,
            );
        }
    }
    let mut out: Vec<GraphicsFrame> = frames.into_values().collect();
    for f in &mut out {
        f.nodes.sort_by_key(|e| e.0);
    }
    Ok(out)
}

/// Per step and tool, the force the host summed from the boards' shares (in board order).
fn tool_forces(host: &[Vec<u8>], steps: u64, tools: usize) -> Result<Vec<[f64; 3]>> {
    let mut shares: Vec<(u32, u8, u8, [f64; 3])> = Vec::new();
    for p in host {
        let r = PacketRepr::parse_bytes(p).map_err(|e| anyhow!("host: bad packet: {e}"))?;
        match r.kind {
            PacketKind::ToolForce => {}
            // Checked as they arrive (`HostCheck`).
            PacketKind::Hello => continue,
            k => bail!(
                "host: unexpected packet {k:?} from address {} (tool forces and hellos only)",
                r.src
            ),
        }
        let t = ToolForcePayload::parse(r.payload)
            .map_err(|e| anyhow!("host: bad tool-force payload from {}: {e}", r.src))?;
        shares.push((t.step, t.tool, r.src, t.force));
    }
    shares.sort_by_key(|a| (a.0, a.1, a.2));
    let mut tool_force = vec![[0.0; 3]; steps as usize * tools];
    for (step, tool, _, f) in shares {
        if let Some(d) = tool_force.get_mut(step as usize * tools + tool as usize) {
            for i in 0..3 {
                d[i] += f[i];
            }
        }
    }
    Ok(tool_force)
}

/// The damaged packets the sinks received (without global recovery), as observations (taken
/// from the net: each is reported once).
pub fn sink_observations(net: &GlobalNet) -> Vec<Observed> {
    let faults = match net.sink_faults.lock() {
        Ok(mut f) => std::mem::take(&mut *f),
        Err(_) => return Vec::new(),
    };
    faults
        .into_iter()
        .map(|f| Observed {
            fault: Fault {
                board: Machine::from_address(f.src).map_or([u8::MAX; 3], |c| c.map(|v| v as u8)),
                step: f.step.map_or(0, u64::from),
                kind: FaultKind::BadPacket { error: f.error },
            },
            phase: phase(Some(Op::Graphics)),
            waiting: false,
            sink: Some(f.sink),
        })
        .collect()
}

/// The sinks' check of a finished run: every board's graphics and tool-force packets (as
/// the board counted them sent) and its hello arrived at the graphics engine and the host. A missing one
/// is a wrong output, not a smaller one: an observation per board and sink (at the run's
/// last step: which packet is missing the sink cannot tell).
pub fn missing_sink_packets(net: &GlobalNet, boards: &[BoardResult], steps: u64) -> Vec<Observed> {
    let count = |m: &Mutex<Vec<Vec<u8>>>, src: u8| {
        m.lock()
            .map(|v| {
                v.iter()
                    .filter(|p| packet_header(p).is_some_and(|h| h.src() == src))
                    .count() as u64
            })
            .unwrap_or(0)
    };
    let mut out = Vec::new();
    for b in boards {
        let Some(addr) = Machine::address(b.board) else {
            continue;
        };
        for (sink, m, sent) in [
            (ADDR_GRAPHICS, &net.graphics, b.global.graphics_packets),
            // Tool forces and the one hello every board sends before step 0.
            (ADDR_HOST, &net.host, b.global.tool_packets + 1),
        ] {
            if count(m, addr) != sent {
                out.push(Observed {
                    fault: Fault {
                        board: b.board.map(|c| c as u8),
                        step: steps,
                        kind: FaultKind::GlobalTimeout { src: addr },
                    },
                    phase: phase(None),
                    waiting: false,
                    sink: Some(sink),
                });
            }
        }
    }
    out
}
