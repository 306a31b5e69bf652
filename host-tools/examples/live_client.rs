//! A scripted WebSocket client of `pe live --builtin` (the benchmark of docs/live.md): it
//! presses the probe onto the tube along the built-in scene's push (4.5 mm over 1 s), holds
//! it 2 s, lifts it over 1 s, waits 1 s, and again, sending a pose 60 times a second as the
//! page does, for SECONDS; then prints what it received.
//!
//! ```text
//! pe live --builtin --quiet &
//! cargo run --release -p host-tools --example live_client -- 127.0.0.1:8080 20
//! ```

use std::net::TcpStream;
use std::time::{Duration, Instant};

use host_tools::live::protocol::{Frame, FrameKind, ServerMessage, Status};
use host_tools::scene::builtin::builtin_scene;
use tungstenite::{Message, WebSocket};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let addr = args.get(1).map_or("127.0.0.1:8080", String::as_str);
    let seconds: f64 = args.get(2).map_or(Ok(20.0), |s| s.parse())?;
    let scene = builtin_scene("medium")?;
    let push = scene.tool[0]
        .path
        .last()
        .map_or([0.0; 3], |p| [p[1], p[2], p[3]]);
    let stream = TcpStream::connect(addr)?;
    stream.set_read_timeout(Some(Duration::from_millis(2)))?;
    stream.set_nodelay(true)?;
    let (mut ws, _) = tungstenite::client(format!("ws://{addr}/session"), stream)?;
    let start = Instant::now();
    let (mut poses, mut forces, mut frames, mut peak_n) = (0u64, 0u64, 0u64, 0.0f64);
    let mut last_status: Option<Status> = None;
    let mut next_pose = start;
    while start.elapsed().as_secs_f64() < seconds {
        let now = Instant::now();
        if now >= next_pose {
            next_pose += Duration::from_micros(16_667);
            let s = press(now.duration_since(start).as_secs_f64());
            let p = push.map(|v| v * s);
            let m = format!(
                r#"{{"type":"pose","tool":"probe","position_m":{p:?},"orientation":[1.0,0.0,0.0,0.0]}}"#
            );
            ws.send(Message::text(m))?;
            poses += 1;
        }
        match read(&mut ws)? {
            Some(Message::Text(t)) => match serde_json::from_str::<ServerMessage>(t.as_str())? {
                ServerMessage::Force { force_n, .. } => {
                    forces += 1;
                    peak_n = peak_n.max(force_n.iter().map(|v| v * v).sum::<f64>().sqrt());
                }
                ServerMessage::Status(s) => last_status = Some(s),
                ServerMessage::Error { message } => eprintln!("error: {message}"),
                _ => {}
            },
            Some(Message::Binary(b)) => {
                let f = Frame::new_checked(&b[..]).map_err(anyhow::Error::msg)?;
                if f.header().kind == FrameKind::Positions {
                    frames += 1;
                }
            }
            _ => {}
        }
    }
    let wall = start.elapsed().as_secs_f64();
    println!(
        "{wall:.1} s: {poses} poses sent, {forces} force messages ({:.0}/s), {frames} surface frames ({:.1}/s), peak |F| {peak_n:.4} N",
        forces as f64 / wall,
        frames as f64 / wall
    );
    if let Some(s) = last_status {
        println!(
            "last status: t = {:.3} s, real-time factor {:.3}, lag {:.2} ms, {} slips ({:.3} s), latency p50 {:.3} ms p99 {:.3} ms max {:.3} ms over {} poses, {} frames dropped",
            s.time_s, s.real_time_factor, 1e3 * s.lag_s, s.slips, s.slipped_s,
            s.latency_ms.p50, s.latency_ms.p99, s.latency_ms.max, s.latency_ms.samples,
            s.surface_frames_dropped
        );
    }
    let _ = ws.close(None);
    Ok(())
}

/// The press's fraction of the push at `t` s: up over 1 s, held 2 s, down over 1 s, off 1 s.
fn press(t: f64) -> f64 {
    match t % 5.0 {
        x if x < 1.0 => x,
        x if x < 3.0 => 1.0,
        x if x < 4.0 => 4.0 - x,
        _ => 0.0,
    }
}

/// The next message, or None when none came within the read timeout.
fn read(ws: &mut WebSocket<TcpStream>) -> anyhow::Result<Option<Message>> {
    match ws.read() {
        Ok(m) => Ok(Some(m)),
        Err(tungstenite::Error::Io(e))
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            Ok(None)
        }
        Err(e) => Err(e.into()),
    }
}
