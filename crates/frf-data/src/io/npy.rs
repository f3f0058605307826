//! NumPy arrays: `.npy` (format versions 1, 2 and 3) and `.npz` (a zip of `.npy` files,
//! stored or deflated, as `numpy.savez` and `numpy.savez_compressed` write them, zip64
//! fields included), read into `f64` arrays in C order. Time records of the public
//! benchmark data sets and of Python users come in these.
//!
//! Supported element types: little- and big-endian `f8`, `f4`, `i8`, `i4`, `i2`, `u2`,
//! `u1`, `i1`; Fortran order is reordered to C order. Anything else (complex, object,
//! strings, structured dtypes) is an error naming the file and the dtype. A damaged file
//! is an error, never a panic.

use crate::FrfError;
use std::collections::BTreeMap;
use std::path::Path;

/// A real array in C (row-major) order.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// The shape.
    pub shape: Vec<usize>,
    /// The values, C order.
    pub data: Vec<f64>,
}

fn bad(name: &str, why: impl Into<String>) -> FrfError {
    FrfError::InvalidData {
        why: format!("{name}: {}", why.into()),
    }
}

/// The value of `key` in the header dictionary text (`{'descr': '<f8', ...}`).
fn header_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let k = header.find(&format!("'{key}'"))?;
    let rest = header[k + key.len() + 2..].trim_start().strip_prefix(':')?;
    Some(rest.trim_start())
}

/// The bytes of a `.npy` file (format version 1.0, little-endian `f8`, C order) holding
/// `array`; its data must have the length its shape says.
pub fn npy_bytes(array: &NpyArray) -> Result<Vec<u8>, FrfError> {
    let n: usize = array.shape.iter().product();
    if n != array.data.len() {
        return Err(FrfError::Dimension {
            what: "npy array".into(),
            expected: format!("{n} values for shape {:?}", array.shape),
            got: format!("{} values", array.data.len()),
        });
    }
    let shape = match array.shape.len() {
        1 => format!("({},)", array.shape[0]),
        _ => format!(
            "({})",
            array
                .shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
    // magic (6) + version (2) + header length (2) + header + '\n': a multiple of 64
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let len = u16::try_from(header.len()).map_err(|_| bad("npy array", "shape too long"))?;
    let mut out = Vec::with_capacity(10 + header.len() + 8 * n);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in &array.data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    Ok(out)
}

/// Writes `array` as a `.npy` file ([`npy_bytes`]); [`FrfError::Io`] naming the file when
/// it cannot be written.
pub fn write_npy(path: impl AsRef<Path>, array: &NpyArray) -> Result<(), FrfError> {
    let path = path.as_ref();
    std::fs::write(path, npy_bytes(array)?).map_err(|e| FrfError::Io {
        file: path.display().to_string(),
        message: e.to_string(),
    })
}

/// Parses one `.npy` file's bytes.
pub fn parse_npy(bytes: &[u8], name: &str) -> Result<NpyArray, FrfError> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad(name, "not a NumPy .npy array (no \\x93NUMPY magic)"));
    }
    let major = bytes[6];
    let (hlen, start): (usize, usize) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err(bad(name, "truncated .npy header"));
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => {
            return Err(bad(
                name,
                format!(".npy format version {v} is not supported"),
            ))
        }
    };
    let header = bytes
        .get(start..start.saturating_add(hlen))
        .ok_or_else(|| bad(name, "truncated .npy header"))?;
    let header = std::str::from_utf8(header).map_err(|_| bad(name, "the header is not text"))?;
    let descr = header_value(header, "descr")
        .and_then(|v| v.strip_prefix('\''))
        .and_then(|v| v.split('\'').next())
        .ok_or_else(|| bad(name, "the header has no 'descr' (dtype)"))?;
    let fortran = header_value(header, "fortran_order")
        .ok_or_else(|| bad(name, "the header has no 'fortran_order'"))?
        .starts_with("True");
    let shape_text = header_value(header, "shape")
        .and_then(|v| v.strip_prefix('('))
        .and_then(|v| v.split(')').next())
        .ok_or_else(|| bad(name, "the header has no 'shape'"))?;
    let shape = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.trim_end_matches('L')
                .parse::<usize>()
                .map_err(|_| bad(name, format!("shape entry `{s}` is not a size")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let n = shape
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b))
        .ok_or_else(|| bad(name, "the shape overflows"))?;
    let (order, kind) = descr.split_at(1.min(descr.len()));
    let little = match order {
        "<" | "|" | "=" => true,
        ">" => false,
        _ => return Err(bad(name, format!("dtype `{descr}` is not supported"))),
    };
    let size: usize = match kind {
        "f8" | "i8" | "u8" => 8,
        "f4" | "i4" | "u4" => 4,
        "i2" | "u2" => 2,
        "i1" | "u1" | "b1" => 1,
        _ => {
            return Err(bad(
                name,
                format!("dtype `{descr}` is not supported (real numbers: f8, f4, or integers)"),
            ))
        }
    };
    let body = &bytes[start + hlen..];
    let need = n
        .checked_mul(size)
        .ok_or_else(|| bad(name, "the data size overflows"))?;
    if body.len() < need {
        return Err(bad(
            name,
            format!(
                "the data are truncated: {} bytes for {n} values of {size} bytes",
                body.len()
            ),
        ));
    }
    let word = |c: &[u8]| -> [u8; 8] {
        let mut w = [0u8; 8];
        if little {
            w[..c.len()].copy_from_slice(c);
        } else {
            for (i, b) in c.iter().rev().enumerate() {
                w[i] = *b;
            }
        }
        w
    };
    let mut data: Vec<f64> = body[..need]
        .chunks_exact(size)
        .map(|c| {
            let w = word(c);
            match kind {
                "f8" => f64::from_le_bytes(w),
                "f4" => f32::from_le_bytes([w[0], w[1], w[2], w[3]]) as f64,
                "i8" => i64::from_le_bytes(w) as f64,
                "u8" => u64::from_le_bytes(w) as f64,
                "i4" => i32::from_le_bytes([w[0], w[1], w[2], w[3]]) as f64,
                "u4" => u32::from_le_bytes([w[0], w[1], w[2], w[3]]) as f64,
                "i2" => i16::from_le_bytes([w[0], w[1]]) as f64,
                "u2" => u16::from_le_bytes([w[0], w[1]]) as f64,
                "i1" => w[0] as i8 as f64,
                _ => w[0] as f64,
            }
        })
        .collect();
    if fortran && shape.len() > 1 {
        // column-major to row-major
        let mut c = vec![0.0; n];
        let nd = shape.len();
        let mut idx = vec![0usize; nd];
        for v in data.iter() {
            // idx is the Fortran-order multi-index of this element
            let mut off = 0;
            for (d, &i) in idx.iter().enumerate() {
                off = off * shape[d] + i;
            }
            c[off] = *v;
            for d in 0..nd {
                idx[d] += 1;
                if idx[d] < shape[d] {
                    break;
                }
                idx[d] = 0;
            }
        }
        data = c;
    }
    Ok(NpyArray { shape, data })
}

/// The bytes of `path` and its name for errors.
fn read_bytes(path: &Path) -> Result<(Vec<u8>, String), FrfError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| FrfError::Io {
        file: name.clone(),
        message: e.to_string(),
    })?;
    Ok((bytes, name))
}

/// Reads a `.npy` file.
pub fn read_npy(path: impl AsRef<Path>) -> Result<NpyArray, FrfError> {
    let (bytes, name) = read_bytes(path.as_ref())?;
    parse_npy(&bytes, &name)
}

fn le16(b: &[u8], at: usize) -> Option<usize> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?) as usize)
}
fn le32(b: &[u8], at: usize) -> Option<u64> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?) as u64)
}
fn le64(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

/// Parses a `.npz` file's bytes: every `NAME.npy` member as `NAME`.
pub fn parse_npz(bytes: &[u8], name: &str) -> Result<BTreeMap<String, NpyArray>, FrfError> {
    let damaged = |why: &str| bad(name, format!("not a readable .npz (zip) file: {why}"));
    // the end-of-central-directory record, searched backwards
    let lo = bytes.len().saturating_sub(22 + 65_535);
    let eocd = (lo..bytes.len().saturating_sub(21))
        .rev()
        .find(|&i| bytes[i..i + 4] == [0x50, 0x4b, 0x05, 0x06])
        .ok_or_else(|| damaged("no end of central directory"))?;
    let entries = le16(bytes, eocd + 10).ok_or_else(|| damaged("truncated directory"))?;
    let mut at = le32(bytes, eocd + 16).ok_or_else(|| damaged("truncated directory"))? as usize;
    if at == 0xffff_ffff {
        // zip64: the zip64 end-of-central-directory locator sits 20 bytes before
        let loc = eocd
            .checked_sub(20)
            .ok_or_else(|| damaged("no zip64 locator"))?;
        let rec = le64(bytes, loc + 8).ok_or_else(|| damaged("no zip64 locator"))? as usize;
        at = le64(bytes, rec + 48).ok_or_else(|| damaged("no zip64 directory"))? as usize;
    }
    let mut out = BTreeMap::new();
    for _ in 0..entries {
        if bytes.get(at..at + 4) != Some(&[0x50, 0x4b, 0x01, 0x02]) {
            return Err(damaged("bad central directory entry"));
        }
        let method = le16(bytes, at + 10).ok_or_else(|| damaged("truncated entry"))?;
        let mut csize = le32(bytes, at + 20).ok_or_else(|| damaged("truncated entry"))?;
        let mut usize_ = le32(bytes, at + 24).ok_or_else(|| damaged("truncated entry"))?;
        let nlen = le16(bytes, at + 28).ok_or_else(|| damaged("truncated entry"))?;
        let xlen = le16(bytes, at + 30).ok_or_else(|| damaged("truncated entry"))?;
        let clen = le16(bytes, at + 32).ok_or_else(|| damaged("truncated entry"))?;
        let mut local = le32(bytes, at + 42).ok_or_else(|| damaged("truncated entry"))?;
        let member = bytes
            .get(at + 46..at + 46 + nlen)
            .and_then(|b| std::str::from_utf8(b).ok())
            .ok_or_else(|| damaged("bad member name"))?
            .to_string();
        // zip64 extra field: the sizes and offset that are 0xffffffff above, in order
        let extra = bytes
            .get(at + 46 + nlen..at + 46 + nlen + xlen)
            .ok_or_else(|| damaged("truncated extra field"))?;
        let mut x = 0;
        while x + 4 <= extra.len() {
            let id = le16(extra, x).unwrap_or(0);
            let len = le16(extra, x + 2).unwrap_or(0);
            if id == 1 {
                let mut p = x + 4;
                for field in [&mut usize_, &mut csize, &mut local] {
                    if *field == 0xffff_ffff {
                        *field = le64(extra, p).ok_or_else(|| damaged("bad zip64 field"))?;
                        p += 8;
                    }
                }
            }
            x += 4 + len;
        }
        at += 46 + nlen + xlen + clen;
        let local = local as usize;
        if bytes.get(local..local + 4) != Some(&[0x50, 0x4b, 0x03, 0x04]) {
            return Err(damaged("bad local header"));
        }
        let lnlen = le16(bytes, local + 26).ok_or_else(|| damaged("truncated header"))?;
        let lxlen = le16(bytes, local + 28).ok_or_else(|| damaged("truncated header"))?;
        let data_at = local + 30 + lnlen + lxlen;
        let raw = bytes
            .get(data_at..data_at.saturating_add(csize as usize))
            .ok_or_else(|| damaged("truncated member"))?;
        let member_name = format!("{name}:{member}");
        let content = match method {
            0 => raw.to_vec(),
            8 => miniz_oxide::inflate::decompress_to_vec_with_limit(raw, usize_ as usize)
                .map_err(|_| bad(&member_name, "damaged deflate data"))?,
            m => {
                return Err(bad(
                    &member_name,
                    format!("zip compression method {m} is not supported (stored or deflate)"),
                ))
            }
        };
        let key = member.strip_suffix(".npy").unwrap_or(&member).to_string();
        out.insert(key, parse_npy(&content, &member_name)?);
    }
    Ok(out)
}

/// Reads a `.npz` file.
pub fn read_npz(path: impl AsRef<Path>) -> Result<BTreeMap<String, NpyArray>, FrfError> {
    let (bytes, name) = read_bytes(path.as_ref())?;
    parse_npz(&bytes, &name)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A version-1 `.npy` of `f8` values.
    pub(crate) fn npy_bytes(shape: &[usize], data: &[f64], fortran: bool) -> Vec<u8> {
        let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
        let shape_text = if dims.len() == 1 {
            format!("({},)", dims[0])
        } else {
            format!("({})", dims.join(", "))
        };
        let mut h = format!(
            "{{'descr': '<f8', 'fortran_order': {}, 'shape': {shape_text}, }}",
            if fortran { "True" } else { "False" }
        );
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend((h.len() as u16).to_le_bytes());
        b.extend(h.as_bytes());
        for v in data {
            b.extend(v.to_le_bytes());
        }
        b
    }

    /// A stored (uncompressed) zip of `members`.
    fn zip_stored(members: &[(&str, Vec<u8>)]) -> Vec<u8> {
        let (mut out, mut dir) = (Vec::new(), Vec::new());
        for (name, data) in members {
            let off = out.len() as u32;
            out.extend([0x50, 0x4b, 0x03, 0x04, 20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
            out.extend([0u8; 4]); // crc (not checked)
            out.extend((data.len() as u32).to_le_bytes());
            out.extend((data.len() as u32).to_le_bytes());
            out.extend((name.len() as u16).to_le_bytes());
            out.extend(0u16.to_le_bytes());
            out.extend(name.as_bytes());
            out.extend(data);
            dir.extend([0x50, 0x4b, 0x01, 0x02, 20, 0, 20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
            dir.extend([0u8; 4]);
            dir.extend((data.len() as u32).to_le_bytes());
            dir.extend((data.len() as u32).to_le_bytes());
            dir.extend((name.len() as u16).to_le_bytes());
            dir.extend([0u8; 12]);
            dir.extend(off.to_le_bytes());
            dir.extend(name.as_bytes());
        }
        let cd = out.len() as u32;
        let cdlen = dir.len() as u32;
        out.extend(dir);
        out.extend([0x50, 0x4b, 0x05, 0x06, 0, 0, 0, 0]);
        out.extend((members.len() as u16).to_le_bytes());
        out.extend((members.len() as u16).to_le_bytes());
        out.extend(cdlen.to_le_bytes());
        out.extend(cd.to_le_bytes());
        out.extend(0u16.to_le_bytes());
        out
    }

    #[test]
    fn arrays_read_in_c_order_from_npy_and_npz() {
        let c: Vec<f64> = (0..6).map(|i| i as f64 * 0.5).collect();
        let a = parse_npy(&npy_bytes(&[2, 3], &c, false), "a.npy").unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, c);
        // the same array written in Fortran order: columns first
        let f = vec![c[0], c[3], c[1], c[4], c[2], c[5]];
        let b = parse_npy(&npy_bytes(&[2, 3], &f, true), "b.npy").unwrap();
        assert_eq!(b.data, c);
        let z = zip_stored(&[
            ("u.npy", npy_bytes(&[2, 3], &c, false)),
            ("y.npy", npy_bytes(&[4], &[1.0, 2.0, 3.0, 4.0], false)),
        ]);
        let m = parse_npz(&z, "r.npz").unwrap();
        assert_eq!(m["u"].data, c);
        assert_eq!(m["y"].shape, vec![4]);
    }

    #[test]
    fn damaged_files_are_errors_not_panics() {
        let good = npy_bytes(&[3], &[1.0, 2.0, 3.0], false);
        for cut in 0..good.len() {
            assert!(parse_npy(&good[..cut], "t.npy").is_err());
        }
        let z = zip_stored(&[("u.npy", good)]);
        for cut in 0..z.len() {
            let _ = parse_npz(&z[..cut], "t.npz");
        }
        // a complex dtype (the same header length: `<f8` becomes `<c8`)
        let mut cplx = npy_bytes(&[1], &[1.0], false);
        let at = cplx.windows(3).position(|w| w == b"<f8").unwrap();
        cplx[at + 1] = b'c';
        let e = parse_npy(&cplx, "c.npy").unwrap_err().to_string();
        assert!(e.contains("c.npy") && e.contains("not supported"), "{e}");
    }

    #[test]
    fn written_arrays_read_back() {
        for shape in [vec![5], vec![3, 2], vec![4, 3, 2, 2]] {
            let n: usize = shape.iter().product();
            let a = NpyArray {
                shape: shape.clone(),
                data: (0..n).map(|k| k as f64 * 0.5 - 1.0).collect(),
            };
            let bytes = super::npy_bytes(&a).unwrap();
            // the data start at a multiple of 64 bytes
            let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
            assert_eq!((10 + hlen) % 64, 0);
            assert_eq!(parse_npy(&bytes, "t.npy").unwrap(), a);
        }
        let bad = NpyArray {
            shape: vec![2, 2],
            data: vec![1.0],
        };
        assert!(super::npy_bytes(&bad).is_err());
    }
}
