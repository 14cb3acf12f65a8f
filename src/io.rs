//! Reading the files the physics is built from: fabric files (YAML) with their
//! raw KES curves (CSV), and OBJ meshes. Errors name the file, the line or
//! field, and what is wrong.

use crate::collision::MeshData;
use crate::fabric::kes::{parse_curve_csv, KesCurve};
use crate::fabric::{Fabric, FabricFile};
use anyhow::{bail, Context, Result};
use std::path::Path;

/// Loads and validates a fabric file; errors name the file and the field.
pub fn load_fabric(path: &Path) -> Result<Fabric> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read fabric file {}", path.display()))?;
    check_yaml_shape(&text).with_context(|| format!("fabric file {}", path.display()))?;
    let file: FabricFile = serde_yaml::from_str(&text)
        .with_context(|| format!("fabric file {}: invalid YAML or field", path.display()))?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    fabric_from_file(file, &dir).with_context(|| format!("fabric file {}", path.display()))
}

/// Builds a fabric from a parsed fabric file whose `curve:` fields are paths
/// relative to `base`.
pub fn fabric_from_file(file: FabricFile, base: &Path) -> Result<Fabric> {
    Ok(Fabric::from_file(file, &|name| {
        read_kes_curve(&base.join(name))
    })?)
}

/// Reads a raw KES curve from a CSV file (see [`parse_curve_csv`]).
pub fn read_kes_curve(path: &Path) -> Result<KesCurve> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read KES curve file {}", path.display()))?;
    Ok(parse_curve_csv(&text, &path.display().to_string())?)
}

/// Reads the vertices and faces of a Wavefront OBJ file (faces fan-triangulated).
pub fn load_obj(path: &Path) -> Result<MeshData> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read OBJ file {}", path.display()))?;
    let mut v = Vec::new();
    let mut faces: Vec<(usize, Vec<i64>)> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it
                    .take(3)
                    .map(|s| s.parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .with_context(|| format!("{}:{}: bad vertex", path.display(), ln + 1))?;
                if c.len() != 3 || c.iter().any(|x| !x.is_finite()) {
                    bail!(
                        "{}:{}: a vertex needs 3 finite coordinates",
                        path.display(),
                        ln + 1
                    );
                }
                v.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                let idx: Vec<i64> = it
                    .map(|s| s.split('/').next().unwrap_or("").parse::<i64>())
                    .collect::<std::result::Result<_, _>>()
                    .with_context(|| format!("{}:{}: bad face", path.display(), ln + 1))?;
                if idx.len() < 3 {
                    bail!(
                        "{}:{}: a face needs at least 3 vertices",
                        path.display(),
                        ln + 1
                    );
                }
                faces.push((ln + 1, idx));
            }
            _ => {}
        }
    }
    let nv = v.len() as i64;
    let mut tris = Vec::new();
    for (ln, f) in faces {
        let mut r = Vec::with_capacity(f.len());
        for i in f {
            let k = if i > 0 { i - 1 } else { nv + i };
            if k < 0 || k >= nv {
                bail!(
                    "{}:{ln}: face uses vertex {i} but the file has {nv} vertices",
                    path.display()
                );
            }
            r.push(k as u32);
        }
        for k in 1..r.len() - 1 {
            tris.push([r[0], r[k], r[k + 1]]);
        }
    }
    if tris.is_empty() {
        bail!("{}: no faces", path.display());
    }
    Ok((v, tris))
}

/// Writes a file whole or not at all: `fill` writes into a temporary file
/// beside `path` (same folder, so the rename cannot cross file systems),
/// which is flushed and renamed onto `path`. Any failure (a full disk)
/// removes the temporary file, leaves no truncated `path`, and names `path`
/// in the error.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
) -> Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let written = (|| -> std::io::Result<()> {
        let mut w = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        fill(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(anyhow::Error::new(e).context(format!("cannot write {}", path.display())));
    }
    Ok(())
}

/// The memory a new grid may use, bytes: the environment variable
/// `GARMENT_SIM_MEMORY_LIMIT` (bytes) if set, else `MemAvailable` of
/// `/proc/meminfo`; none when neither can be read.
pub fn available_memory() -> Option<u64> {
    if let Ok(v) = std::env::var("GARMENT_SIM_MEMORY_LIMIT") {
        return v.trim().parse().ok();
    }
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map(|kb| kb * 1024)
}

/// Largest YAML file (scene, fabric, parameters) read, bytes: the shipped
/// ones are a few KB; meshes come as OBJ files, not YAML.
pub const MAX_YAML_BYTES: usize = 1 << 20;

/// Deepest nesting of `[` and `{` in a YAML file read: a scene nests four
/// levels; deep nesting makes the parser slow (quadratic) long before it
/// says anything.
pub const MAX_YAML_DEPTH: usize = 32;

/// Refuses, before parsing, a YAML text larger than [`MAX_YAML_BYTES`] or
/// nested deeper than [`MAX_YAML_DEPTH`] in flow brackets (quoted strings
/// and comments are skipped), naming the line.
pub fn check_yaml_shape(text: &str) -> Result<()> {
    if text.len() > MAX_YAML_BYTES {
        bail!(
            "{} bytes: larger than the {MAX_YAML_BYTES} bytes a YAML file may have",
            text.len()
        );
    }
    let mut depth = 0usize;
    for (ln, line) in text.lines().enumerate() {
        let mut quote: Option<char> = None;
        let mut prev = ' ';
        for ch in line.chars() {
            match quote {
                Some(q) => {
                    if ch == q {
                        quote = None;
                    }
                }
                None => match ch {
                    '\'' | '"' if " [{,:".contains(prev) => quote = Some(ch),
                    '#' if prev == ' ' || prev == '\t' => break,
                    '[' | '{' => {
                        depth += 1;
                        if depth > MAX_YAML_DEPTH {
                            bail!(
                                "line {}: brackets nested deeper than {MAX_YAML_DEPTH} levels",
                                ln + 1
                            );
                        }
                    }
                    ']' | '}' => depth = depth.saturating_sub(1),
                    _ => {}
                },
            }
            prev = ch;
        }
    }
    Ok(())
}
