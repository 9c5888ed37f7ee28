//! Pictures reach disk atomically: written to a temporary sibling and renamed into place, so a
//! reader sees the old picture or the new one, never a torn one.

use std::io::Write;
use std::path::Path;

use crate::error::{PlotError, Result};

/// An I/O error writing `path` as [`PlotError::Write`].
fn write_error(path: &Path, context: String, source: std::io::Error) -> PlotError {
    PlotError::Write {
        path: path.to_path_buf(),
        context,
        source,
    }
}

/// Writes `bytes` to `path` atomically, through `.NAME.tmp.PID` beside it (created as any new
/// file is, so the picture gets the usual permissions), synced, then renamed over `path`.
pub(crate) fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp.{}", std::process::id()));
    {
        let mut file = std::fs::File::create(&tmp)
            .map_err(|e| write_error(&tmp, format!("cannot create {}", tmp.display()), e))?;
        file.write_all(bytes)
            .map_err(|e| write_error(&tmp, format!("cannot write {}", tmp.display()), e))?;
        file.sync_all()
            .map_err(|e| write_error(&tmp, format!("cannot sync {}", tmp.display()), e))?;
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        write_error(
            path,
            format!("cannot move {} into place", path.display()),
            e,
        )
    })?;
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
        let mut writer = enc
            .write_header()
            .map_err(|e| PlotError::draw("PNG header", e))?;
        writer
            .write_image_data(rgb)
            .map_err(|e| PlotError::draw("PNG data", e))?;
        writer.finish().map_err(|e| PlotError::draw("PNG end", e))?;
    }
    Ok(bytes)
}

/// Encodes an RGB buffer as PNG (fast compression) and writes it atomically.
pub fn write_png(path: &Path, rgb: &[u8], w: u32, h: u32) -> Result<()> {
    let bytes = encode_png(rgb, w, h, Some(png::Compression::Fast))?;
    write_atomic_bytes(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression: pictures were written through a 0600 temporary file and so were readable
    /// by their owner only; they get the permissions any new file gets.
    #[cfg(unix)]
    #[test]
    fn pictures_get_the_permissions_of_any_new_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("temporary directory");
        let plain = dir.path().join("plain");
        std::fs::File::create(&plain).expect("plain file");
        let picture = dir.path().join("picture.png");
        write_atomic_bytes(&picture, b"png").expect("written");
        let mode = |p: &Path| std::fs::metadata(p).expect("exists").permissions().mode() & 0o777;
        assert_eq!(mode(&picture), mode(&plain));
        assert_eq!(std::fs::read(&picture).expect("read"), b"png");
        assert_eq!(
            std::fs::read_dir(dir.path()).expect("dir").count(),
            2,
            "no temporary left"
        );
    }
}
