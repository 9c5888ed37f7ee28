//! Pictures reach disk atomically: written to a temporary sibling and renamed into place, so a
//! reader sees the old picture or the new one, never a torn one.

use std::io::Write;
use std::path::Path;

use anyhow::{Context, Result};

/// Writes `bytes` to `path` atomically.
pub(crate) fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("cannot create a temporary file in {}", dir.display()))?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path)
        .with_context(|| format!("cannot move {} into place", path.display()))?;
    Ok(())
}

/// An 8-bit RGB buffer `w` x `h` as PNG bytes. Renders use [`png::Compression::Fast`] (large
/// images, written often); contour maps the default.
pub(crate) fn encode_png(
    rgb: &[u8],
    w: u32,
    h: u32,
    compression: Option<png::Compression>,
) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        if let Some(c) = compression {
            enc.set_compression(c);
        }
        let mut writer = enc.write_header().context("PNG header")?;
        writer.write_image_data(rgb).context("PNG data")?;
        writer.finish().context("PNG end")?;
    }
    Ok(bytes)
}

/// Encodes an RGB buffer as PNG (fast compression) and writes it atomically.
pub fn write_png(path: &Path, rgb: &[u8], w: u32, h: u32) -> Result<()> {
    let bytes = encode_png(rgb, w, h, Some(png::Compression::Fast))?;
    write_atomic_bytes(path, &bytes).with_context(|| format!("cannot write {}", path.display()))
}
