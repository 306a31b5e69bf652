//! The fit check: every image against the board profile's capacity table
//! ([`Capacities::for_board`], the figures the firmware's statics are sized by), so a
//! schedule that `pe compile` accepts is one the board loads, and one it refuses names the
//! board, the table and the overflow.

use anyhow::{bail, Result};
use pe_firmware::image::ImageHeader;
use pe_firmware::profile::BoardProfile;
use pe_firmware::runtime::{Capacities, ROUNDS_PER_AXIS_MAX};

use super::image::BoardImage;
use super::plan::FACE_NAMES;

/// What the `profile` firmware built for this image's precision and integration holds.
pub fn board_capacities(profile: &BoardProfile, h: &ImageHeader) -> Capacities {
    pe_firmware::with_element_types!(h.precision, h.integration, |T, E| {
        Capacities::for_board::<T, E>(profile)
    })
}

/// Why the images do not fit `profile`, one line per board and table (empty: they fit).
pub fn fit_problems(images: &[BoardImage], profile: &BoardProfile) -> Vec<String> {
    let mut problems = Vec::new();
    for im in images {
        let [x, y, z] = im.coords;
        let at = format!("board ({x},{y},{z})");
        let len = im.bytes.len() as u64;
        if len > profile.image_flash_bytes {
            problems.push(format!(
                "{at}: image {len} bytes exceeds the {} flash region of {} bytes by {} bytes",
                profile.name,
                profile.image_flash_bytes,
                len - profile.image_flash_bytes
            ));
        }
        let c = &im.header.counts;
        let caps = board_capacities(profile, &im.header);
        for (what, n, max) in caps.shortfalls(c) {
            if what.starts_with("contact") {
                continue; // the same on every board that has them: said once below
            }
            let why = if what == "elements" {
                " (the RAM left after the fixed tables)"
            } else {
                ""
            };
            problems.push(format!(
                "{at}: {n} {what} exceed the {max} the {} firmware holds{why}, by {}",
                profile.name,
                n - max
            ));
        }
        for (a, &r) in c.rounds.iter().enumerate() {
            if r as usize > ROUNDS_PER_AXIS_MAX {
                problems.push(format!(
                    "{at}: {r} exchange rounds along {} exceed the {ROUNDS_PER_AXIS_MAX} the firmware runs",
                    ["x", "y", "z"][a]
                ));
            }
        }
        let linked: Vec<&str> = im
            .header
            .linked_faces()
            .iter()
            .zip(FACE_NAMES)
            .filter(|(&l, _)| l)
            .map(|(_, n)| n)
            .collect();
        if linked.len() > profile.face_ports as usize {
            problems.push(format!(
                "{at}: exchanges over {} faces ({}), but the {} firmware drives {} face links",
                linked.len(),
                linked.join(" "),
                profile.name,
                profile.face_ports
            ));
        }
        for (f, &n) in c.exchange.iter().enumerate() {
            if n as usize > link_proto::BORDER_NODES_PER_FACE_MAX {
                problems.push(format!(
                    "{at} link {}: {n} border nodes exceed the {} a frame carries",
                    FACE_NAMES[f],
                    link_proto::BORDER_NODES_PER_FACE_MAX
                ));
            }
        }
    }
    // The contact tables are the same on every board that has them (the boards that own a
    // contact node).
    if let Some(im) = images.iter().find(|im| im.header.counts.contact_nodes > 0) {
        let caps = board_capacities(profile, &im.header);
        for (what, n, max) in caps.shortfalls(&im.header.counts) {
            if what.starts_with("contact") {
                let what = what.replace("contact ", "contact-surface ");
                problems.push(format!(
                    "every board that owns a contact node: {n} {what} exceed the {max} the {} firmware holds (declare smaller [[surface]]s)",
                    profile.name
                ));
            }
        }
    }
    problems
}

/// Checks every image against the board profile; the error names each board and table
/// that does not fit and by how much.
pub fn check_fit(images: &[BoardImage], profile: &BoardProfile) -> Result<()> {
    let problems = fit_problems(images, profile);
    if problems.is_empty() {
        Ok(())
    } else {
        bail!(
            "the schedule does not fit the {} board profile:\n  {}",
            profile.name,
            problems.join("\n  ")
        )
    }
}
