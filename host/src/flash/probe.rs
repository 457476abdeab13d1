//! The probe-rs half of flashing (the `flash` feature, on by default): the
//! chip's built-in memory map, staging a [`Plan`] in probe-rs' flash loader,
//! attaching to a probe and programming. The plan itself, and the checks
//! that need no chip description, are in the parent module and build
//! without probe-rs.

use super::{Content, FlashError, Layout, Options, Plan, ReadBack, board_image, check_region};
use probe_rs::config::Registry;
use probe_rs::flashing::{DownloadOptions, FlashLoader, FlashProgress, ProgressEvent};
use probe_rs::{Permissions, Session, SessionConfig};

/// Stages a plan's chunks in a flash loader (probe-rs checks each against
/// the chip's memory map).
pub fn stage(mut loader: FlashLoader, plan: &Plan, chip: &str) -> Result<FlashLoader, FlashError> {
    for c in &plan.chunks {
        loader
            .add_data(c.address, &c.data)
            .map_err(|e| FlashError::Chip {
                chip: chip.to_string(),
                reason: format!("{:#010x} (+{} bytes): {}", c.address, c.len(), chain(&e)),
            })?;
    }
    Ok(loader)
}

/// Checks a plan against the chip's built-in description without a probe:
/// the chip must be known and every chunk must lie in its memory.
pub fn check_chip(plan: &Plan, chip: &str) -> Result<(), FlashError> {
    staged_loader(plan, chip).map(|_| ())
}

/// The plan staged in a flash loader for the chip's built-in description.
fn staged_loader(plan: &Plan, chip: &str) -> Result<FlashLoader, FlashError> {
    let target = Registry::from_builtin_families()
        .get_target_by_name(chip)
        .map_err(|e| FlashError::Chip {
            chip: chip.to_string(),
            reason: e.to_string(),
        })?;
    stage(target.flash_loader(), plan, chip)
}

/// Without a probe: the table region as the board would read it if the
/// plan were written (the bytes staged in probe-rs' flash loader for the
/// chip, over erased flash), and whether it arms. `None` if the plan does
/// not write the table region.
pub fn dry_read_back(plan: &Plan, chip: &str) -> Result<Option<ReadBack>, FlashError> {
    let loader = staged_loader(plan, chip)?;
    read_back(plan, staged_image(&loader, &plan.layout), true)
}

/// Attaches to `chip` through the first probe found.
pub fn attach(chip: &str) -> Result<Session, FlashError> {
    let config = SessionConfig {
        permissions: Permissions::default(),
        ..SessionConfig::default()
    };
    Session::auto_attach(chip, config).map_err(|e| FlashError::Probe(chain(&e)))
}

/// Writes a plan through an attached session, reporting progress events to
/// `progress`. Erases only the sectors written; bytes of a written sector
/// that the plan does not cover are not kept. If the plan writes the table
/// region, reads it back ([`ReadBack`]) and checks that it holds exactly
/// the planned bytes.
pub fn program(
    session: &mut Session,
    plan: &Plan,
    options: Options,
    progress: impl FnMut(ProgressEvent),
) -> Result<Option<ReadBack>, FlashError> {
    let chip = session.target().name.clone();
    let loader = stage(session.target().flash_loader(), plan, &chip)?;
    let mut download = DownloadOptions::default();
    download.verify = options.verify;
    download.dry_run = options.dry_run;
    download.progress = FlashProgress::new(progress);
    loader
        .commit(session, download)
        .map_err(|e| FlashError::Flash(chain(&e)))?;
    if !plan.chunks.iter().any(|c| c.content == Content::Tables) {
        return Ok(None);
    }
    let image = if options.dry_run {
        staged_image(&loader, &plan.layout)
    } else {
        read_tables(session, &plan.layout)?
    };
    read_back(plan, image, options.dry_run)
}

/// The table flash as probe-rs' loader would leave it: its staged chunks
/// inside the table region over erased flash.
fn staged_image(loader: &FlashLoader, layout: &Layout) -> Vec<u8> {
    let region = layout.tables;
    let mut image = board_image(layout, &[]);
    for (address, data) in loader.data() {
        for (i, b) in data.iter().enumerate() {
            let a = address + i as u64;
            if region.contains(a, 1) {
                let at = usize::try_from(a - region.start).unwrap_or(usize::MAX);
                if let Some(slot) = image.get_mut(at) {
                    *slot = *b;
                }
            }
        }
    }
    image
}

/// Reads the whole table region from the chip.
fn read_tables(session: &mut Session, layout: &Layout) -> Result<Vec<u8>, FlashError> {
    let size = usize::try_from(layout.tables.size).unwrap_or(usize::MAX);
    let mut image = vec![0u8; size];
    let mut core = session.core(0).map_err(|e| FlashError::Probe(chain(&e)))?;
    probe_rs::MemoryInterface::read(&mut core, layout.tables.start, &mut image)
        .map_err(|e| FlashError::ReadBack(Box::new(FlashError::Probe(chain(&e)))))?;
    Ok(image)
}

/// An error and its sources, `: `-separated (probe-rs' top-level messages
/// are often generic, the cause is in the sources).
fn chain(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let text = s.to_string();
        if !out.contains(&text) {
            out.push_str(": ");
            out.push_str(&text);
        }
        source = s.source();
    }
    out
}

/// Checks that `image` (the table flash) starts with the plan's region and
/// reads it as the board does.
fn read_back(plan: &Plan, image: Vec<u8>, staged: bool) -> Result<Option<ReadBack>, FlashError> {
    let Some(written) = plan.chunks.iter().find(|c| c.content == Content::Tables) else {
        return Ok(None);
    };
    if image.get(..written.data.len()) != Some(&written.data[..]) {
        let at = image
            .iter()
            .zip(&written.data)
            .position(|(a, b)| a != b)
            .unwrap_or(image.len());
        return Err(FlashError::ReadBack(Box::new(FlashError::Flash(format!(
            "byte {at} of the region differs from what was written"
        )))));
    }
    let verdict = check_region(&plan.layout, &image);
    Ok(Some(ReadBack {
        image,
        staged,
        verdict,
    }))
}
