//! Shows: servo curves a board plays from flash with no host (issue #17).
//!
//! A show is the servo targets of one or more takes, one frame per rig
//! frame period, compressed per channel as **keyframes joined by straight
//! lines**: between two keys `(f₀, v₀)` and `(f₁, v₁)` the target of frame
//! `f` is `v₀ + round((v₁ − v₀)·(f − f₀) / (f₁ − f₀))` (integer arithmetic,
//! half away from zero; [`interpolate`]). The host's encoder places keys so
//! that every frame decodes within the show's stated error bound of the
//! take's target (quarter units). This module is the **one decoder**: the
//! encoder checks its keys with it, and the firmware plays with it.
//!
//! # Show format version 1 (`MSHW`)
//!
//! All integers little-endian.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"MSHW"` |
//! | 4 | 2 | format version, `u16` ([`VERSION`] = 1) |
//! | 6 | 2 | flags: bit 0 loop ([`LOOP`]), bit 1 play at boot ([`AT_BOOT`]); other bits 0 |
//! | 8 | 8 | the rig's hash ([`crate::rig::Rig::rig_hash`]) |
//! | 16 | 4 | frame period, µs (the rig's) |
//! | 20 | 4 | frame count `F` (≥ 1) |
//! | 24 | 2 | channel count `C` (≤ [`MAX_SERVOS`]) |
//! | 26 | 2 | error bound, quarter units |
//! | 28 | 4 · `C` | per channel its key count `Kc` (0: the show does not drive it; else ≥ 1) |
//! | 28 + 4 · `C` | 6 · ΣKc | the keys, channel by channel: `frame: u32`, `target: u16`; a channel's first key at frame 0, its last at `F − 1`, frames strictly increasing (one key: `F` = 1) |
//! | end − 4 | 4 | CRC-32/ISO-HDLC of every byte before it |
//!
//! A show sits in the table region as an entry of kind 4
//! ([`crate::region::EntryKind::SHOW`]); readers of region version 1 that
//! do not know it skip it.

use crate::crc::crc32;
use crate::wire::MAX_SERVOS;

/// The show's magic.
pub const MAGIC: [u8; 4] = *b"MSHW";
/// The show format version this core reads.
pub const VERSION: u16 = 1;
/// Flag: start again after the last frame.
pub const LOOP: u16 = 1;
/// Flag: start playing at boot.
pub const AT_BOOT: u16 = 2;
/// Bytes before the channel table.
pub const HEADER_LEN: usize = 28;
/// Bytes of one key.
pub const KEY_LEN: usize = 6;

/// Why a show blob was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShowError {
    /// Shorter than its header and tables say.
    Truncated,
    /// Not a show.
    Magic,
    /// Another format version.
    Version(u16),
    /// The CRC does not match.
    Crc,
    /// A header field out of range (zero frames, too many channels,
    /// unknown flags).
    Header,
    /// A channel's keys do not start at 0, end at `F − 1` and increase.
    Keys(u16),
    /// Built for another rig.
    RigMismatch,
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    let s = b.get(at..at.checked_add(2)?)?;
    Some(u16::from_le_bytes([*s.first()?, *s.get(1)?]))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    let s = b.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(s.try_into().ok()?))
}

/// The target at frame `f` between keys `(f0, v0)` and `(f1, v1)`, with
/// `f0 ≤ f ≤ f1` (see the module doc); `v0` if `f1 ≤ f0`.
#[must_use]
#[inline]
pub fn interpolate(f0: u32, v0: u16, f1: u32, v1: u16, f: u32) -> u16 {
    let span = i64::from(f1) - i64::from(f0);
    let num = (i64::from(v1) - i64::from(v0)) * (i64::from(f) - i64::from(f0));
    let half = if num < 0 { -span } else { span };
    let step = (2 * num + half).checked_div(2 * span).unwrap_or(0);
    u16::try_from(i64::from(v0) + step).unwrap_or(v0)
}

/// A checked show blob (see the module doc), read in place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Show<'a> {
    bytes: &'a [u8],
    flags: u16,
    rig_hash: u64,
    period_us: u32,
    frames: u32,
    channels: u16,
    bound: u16,
}

impl<'a> Show<'a> {
    /// Checks a show blob: magic, version, CRC, header, and every
    /// channel's keys.
    ///
    /// # Errors
    /// The [`ShowError`] that refused it.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, ShowError> {
        if bytes.get(..4).ok_or(ShowError::Truncated)? != MAGIC {
            return Err(ShowError::Magic);
        }
        let version = u16_at(bytes, 4).ok_or(ShowError::Truncated)?;
        if version != VERSION {
            return Err(ShowError::Version(version));
        }
        let body_len = bytes
            .len()
            .checked_sub(4)
            .filter(|&n| n >= HEADER_LEN)
            .ok_or(ShowError::Truncated)?;
        let body = bytes.get(..body_len).ok_or(ShowError::Truncated)?;
        if u32_at(bytes, body_len) != Some(crc32(body)) {
            return Err(ShowError::Crc);
        }
        let field = |at| u16_at(body, at).ok_or(ShowError::Truncated);
        let word = |at| u32_at(body, at).ok_or(ShowError::Truncated);
        let lo = u64::from(word(8)?);
        let hi = u64::from(word(12)?);
        let show = Self {
            bytes: body,
            flags: field(6)?,
            rig_hash: lo | (hi << 32),
            period_us: word(16)?,
            frames: word(20)?,
            channels: field(24)?,
            bound: field(26)?,
        };
        if show.frames == 0
            || usize::from(show.channels) > MAX_SERVOS
            || show.flags & !(LOOP | AT_BOOT) != 0
        {
            return Err(ShowError::Header);
        }
        show.check_keys()?;
        Ok(show)
    }

    /// Checks every channel's keys and that they fill the blob exactly.
    fn check_keys(&self) -> Result<(), ShowError> {
        let mut at = self.keys_start();
        for ch in 0..self.channels {
            let count = self.key_count(ch).ok_or(ShowError::Truncated)?;
            let mut last: Option<u32> = None;
            for k in 0..count {
                let (f, _) = self
                    .key_at(at.saturating_add((k as usize).saturating_mul(KEY_LEN)))
                    .ok_or(ShowError::Truncated)?;
                let ok = match last {
                    None => f == 0,
                    Some(l) => f > l,
                };
                if !ok {
                    return Err(ShowError::Keys(ch));
                }
                last = Some(f);
            }
            if count > 0 && last != Some(self.frames.saturating_sub(1)) {
                return Err(ShowError::Keys(ch));
            }
            at = at.saturating_add((count as usize).saturating_mul(KEY_LEN));
        }
        if at == self.bytes.len() {
            Ok(())
        } else {
            Err(ShowError::Truncated)
        }
    }

    fn keys_start(&self) -> usize {
        HEADER_LEN + 4 * usize::from(self.channels)
    }

    /// Channel `ch`'s key count (0: not driven).
    #[must_use]
    pub fn key_count(&self, ch: u16) -> Option<u32> {
        if ch >= self.channels {
            return None;
        }
        u32_at(self.bytes, HEADER_LEN + 4 * usize::from(ch))
    }

    fn key_at(&self, at: usize) -> Option<(u32, u16)> {
        Some((
            u32_at(self.bytes, at)?,
            u16_at(self.bytes, at.checked_add(4)?)?,
        ))
    }

    /// Where channel `ch`'s keys start, and their count.
    fn channel_keys(&self, ch: u16) -> Option<(usize, u32)> {
        let mut at = self.keys_start();
        for c in 0..ch {
            at = at.checked_add((self.key_count(c)? as usize).checked_mul(KEY_LEN)?)?;
        }
        Some((at, self.key_count(ch)?))
    }

    /// Key `k` of channel `ch`: `(frame, target)`.
    #[must_use]
    pub fn key(&self, ch: u16, k: u32) -> Option<(u32, u16)> {
        let (at, count) = self.channel_keys(ch)?;
        if k >= count {
            return None;
        }
        self.key_at(at.checked_add((k as usize).checked_mul(KEY_LEN)?)?)
    }

    /// Channel `ch`'s target at frame `f` (`None` if the show does not
    /// drive it or `f` is past the end). Searches its keys; a player keeps
    /// a [`Cursor`] instead.
    #[must_use]
    pub fn target(&self, ch: u16, f: u32) -> Option<u16> {
        let mut cursor = Cursor::default();
        cursor.target(self, ch, f)
    }

    /// The flags ([`LOOP`], [`AT_BOOT`]).
    #[must_use]
    pub fn flags(&self) -> u16 {
        self.flags
    }

    /// Whether the show starts again after its last frame.
    #[must_use]
    pub fn looping(&self) -> bool {
        self.flags & LOOP != 0
    }

    /// Whether the show starts at boot.
    #[must_use]
    pub fn at_boot(&self) -> bool {
        self.flags & AT_BOOT != 0
    }

    /// The rig it was built for.
    #[must_use]
    pub fn rig_hash(&self) -> u64 {
        self.rig_hash
    }

    /// Its frame period, µs.
    #[must_use]
    pub fn period_us(&self) -> u32 {
        self.period_us
    }

    /// Its frame count.
    #[must_use]
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Its channel count.
    #[must_use]
    pub fn channels(&self) -> u16 {
        self.channels
    }

    /// Its stated error bound, quarter units.
    #[must_use]
    pub fn bound(&self) -> u16 {
        self.bound
    }
}

/// Where a player is in each channel's keys: frames only move forward
/// (or start again at 0), so each step looks at the next key or two.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cursor {
    /// Per channel, the key at or before the last frame asked for.
    key: [u32; MAX_SERVOS],
    /// The last frame asked for.
    frame: u32,
}

impl Cursor {
    /// Channel `ch`'s target at frame `f`, moving the cursor (a frame
    /// before the last one asked for starts the search again).
    pub fn target(&mut self, show: &Show<'_>, ch: u16, f: u32) -> Option<u16> {
        if f >= show.frames {
            return None;
        }
        let (at, count) = show.channel_keys(ch)?;
        let slot = self.key.get_mut(usize::from(ch))?;
        if f < self.frame || *slot >= count {
            *slot = 0;
        }
        let key = |k: u32| show.key_at(at.checked_add((k as usize).checked_mul(KEY_LEN)?)?);
        while let Some((next, _)) =
            key(slot.saturating_add(1)).filter(|_| slot.saturating_add(1) < count)
        {
            if next > f {
                break;
            }
            *slot = slot.saturating_add(1);
        }
        let (f0, v0) = key(*slot)?;
        let value = match key(slot.saturating_add(1)).filter(|_| slot.saturating_add(1) < count) {
            Some((f1, v1)) => interpolate(f0, v0, f1, v1, f),
            None => v0,
        };
        Some(value)
    }

    /// Records that frame `f` was played (call after every channel of it).
    pub fn played(&mut self, f: u32) {
        self.frame = f;
    }
}

/// Whether a show was built for the rig of hash `rig_hash`.
///
/// # Errors
/// [`ShowError::RigMismatch`] if not.
pub fn check_rig(show: &Show<'_>, rig_hash: u64) -> Result<(), ShowError> {
    if show.rig_hash() == rig_hash {
        Ok(())
    } else {
        Err(ShowError::RigMismatch)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_rounds_half_away_from_zero() {
        assert_eq!(interpolate(0, 100, 4, 102, 1), 101); // 100.5 -> 101
        assert_eq!(interpolate(0, 102, 4, 100, 1), 101); // 101.5: a step of -0.5 -> -1
        assert_eq!(interpolate(0, 102, 4, 100, 3), 100); // 100.5: a step of -1.5 -> -2
        assert_eq!(interpolate(10, 0, 20, 1000, 15), 500);
        assert_eq!(interpolate(10, 7, 10, 9, 10), 7);
    }
}
