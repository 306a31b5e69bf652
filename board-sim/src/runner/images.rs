//! The compiled directory a run reads: the manifest's machine and every board's image.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use host_tools::compile::{check_image_set, image_file_name, ImageFile, Manifest};
use link_proto::Machine;
use pe_firmware::image::{ImageHeader, ImageReader};

/// The machine `manifest.json` in `dir` names.
pub fn manifest_machine(dir: &Path, manifest: &Manifest) -> Result<Machine> {
    let d = manifest.machine;
    Machine::new(d).ok_or_else(|| {
        anyhow!(
            "{}: machine {}x{}x{}: 1..{} boards per axis",
            dir.join("manifest.json").display(),
            d[0],
            d[1],
            d[2],
            Machine::AXIS_MAX
        )
    })
}

/// Reads every board's image named in the manifest, in board-index order, checking each
/// against its position and the machine (and, with `check_manifest`, the set against the
/// manifest: [`check_image_set`]); returns them with the first header and the scene's tool
/// count.
pub(crate) fn read_images(
    dir: &Path,
    manifest: &Manifest,
    machine: Machine,
    check_manifest: bool,
) -> Result<(Vec<Vec<u8>>, ImageHeader, usize)> {
    if manifest.boards.len() != machine.count() {
        bail!(
            "{}: manifest lists {} boards for a {machine} machine",
            dir.display(),
            manifest.boards.len(),
        );
    }
    let mut files = Vec::with_capacity(machine.count());
    for b in &manifest.boards {
        files.push(read_image(dir, machine, b.board)?);
    }
    if check_manifest {
        check_image_set(manifest, &files)?;
    }
    let header = files
        .first()
        .map(|f| f.header)
        .ok_or_else(|| anyhow!("{}: no boards", dir.display()))?;
    // The scene's tools: the most any image holds (a board that owns no contact node
    // carries no contact tables).
    let tools = files
        .iter()
        .map(|f| f.header.counts.tools as usize)
        .max()
        .unwrap_or(0);
    let mut images = vec![Vec::new(); machine.count()];
    for f in files {
        images[machine.index(f.board)] = f.bytes;
    }
    Ok((images, header, tools))
}

/// The image of the board at `board`, checked against its position and the machine.
fn read_image(dir: &Path, machine: Machine, board: [usize; 3]) -> Result<ImageFile> {
    let [x, y, z] = board;
    let p = dir.join(image_file_name(board));
    if !machine.contains(board) {
        bail!(
            "{}: board ({x},{y},{z}) is outside the {machine} machine",
            dir.join("manifest.json").display(),
        );
    }
    let bytes = std::fs::read(&p).with_context(|| format!("reading {}", p.display()))?;
    let header = ImageReader::new(&bytes, Some(board.map(|c| c as u8)))
        .map_err(|e| anyhow!("board ({x},{y},{z}): {}: {e}", p.display()))?
        .header;
    if header.machine.map(|c| c as usize) != machine.dims() {
        let m = header.machine;
        bail!(
            "board ({x},{y},{z}): {}: image is for a {}x{}x{} machine, manifest.json says {machine}: the image is from another compilation",
            p.display(),
            m[0],
            m[1],
            m[2],
        );
    }
    Ok(ImageFile {
        board,
        path: p,
        bytes,
        header,
    })
}
