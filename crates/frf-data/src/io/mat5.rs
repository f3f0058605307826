//! MATLAB level-5 MAT-files (what `save` writes with `-v6` or `-v7`, the default up to
//! R2006a and still the default format of `save`): a reader and a writer for the subset
//! of numeric arrays, written here so that no input can make the program panic.
//!
//! Layout (MathWorks, "MAT-File Format", level 5): a 128-byte header (116 bytes of
//! text, 8 of subsystem offset, the version `0x0100` and the endian indicator `IM`
//! for little-endian or `MI` for big-endian files), then data elements, each an 8-byte
//! tag (type, byte count; a "small element" packs a count of at most 4 bytes in the upper
//! half of the type word and its data in the tag's second word) followed by the data,
//! padded to 8 bytes. A variable is an `miMATRIX` element (type 14), plain or inside an
//! `miCOMPRESSED` one (type 15, a zlib stream inflated here by `miniz_oxide`), holding
//! the array flags (class, complex), the dimensions, the name and, for numeric classes,
//! the real and imaginary parts in any numeric storage type.
//!
//! Variables that are not numeric arrays (char, logical, cell, struct, sparse, objects
//! such as `tf` or `frd`) are listed with their kind, not read. v7.3 files are HDF5 and
//! get an error that says to save with `-v7`; v4 files an error too.

use crate::{FormatProblem, FrfError};

/// What a variable of a MAT-file holds.
#[derive(Debug, Clone, PartialEq)]
pub enum MatValue {
    /// A numeric array, column-major, converted to `f64`.
    Numeric {
        /// Dimensions (at least two).
        dims: Vec<usize>,
        /// Real part.
        real: Vec<f64>,
        /// Imaginary part, for a complex array.
        imag: Option<Vec<f64>>,
    },
    /// Anything else, with its kind (`char`, `logical`, `cell`, `struct`, `sparse`,
    /// `object`, `function handle`).
    Other(&'static str),
}

/// One variable of a MAT-file.
#[derive(Debug, Clone, PartialEq)]
pub struct MatVar {
    /// The name (empty for the hidden subsystem data of objects).
    pub name: String,
    /// What it holds.
    pub value: MatValue,
}

const MI_INT8: u32 = 1;
const MI_UINT32: u32 = 6;
const MI_INT32: u32 = 5;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;

/// The error of a malformed file: no line, the place in `column`.
fn bad(file: &str, place: &str, detail: impl Into<String>) -> FrfError {
    FrfError::format(file, 0, Some(place), FormatProblem::BadRecord, detail)
}

/// Byte order of the file.
#[derive(Clone, Copy)]
struct Endian {
    little: bool,
}

impl Endian {
    fn u32(self, b: &[u8]) -> u32 {
        let a = [b[0], b[1], b[2], b[3]];
        if self.little {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        }
    }
}

/// One data element: its type and data, and where the next one starts.
struct Element<'a> {
    ty: u32,
    data: &'a [u8],
    next: usize,
}

/// Reads the element at `pos` of `b` (`place` names the enclosing thing in errors);
/// `pad` rounds the data up to 8 bytes (every element except compressed ones).
fn element<'a>(
    file: &str,
    place: &str,
    b: &'a [u8],
    pos: usize,
    e: Endian,
) -> Result<Element<'a>, FrfError> {
    let tag = b.get(pos..pos.saturating_add(8)).ok_or_else(|| {
        bad(
            file,
            place,
            format!("the data end at byte {} inside a data element tag", b.len()),
        )
    })?;
    let first = e.u32(&tag[0..4]);
    if first >> 16 != 0 {
        // Small data element: up to 4 bytes in the tag.
        let size = (first >> 16) as usize;
        if size > 4 {
            return Err(bad(
                file,
                place,
                format!("small data element at byte {pos} claims {size} bytes (at most 4)"),
            ));
        }
        return Ok(Element {
            ty: first & 0xffff,
            data: &tag[4..4 + size],
            next: pos + 8,
        });
    }
    let size = e.u32(&tag[4..8]) as usize;
    let start = pos + 8;
    let data = b.get(start..start.saturating_add(size)).ok_or_else(|| {
        bad(
            file,
            place,
            format!(
                "the data element at byte {pos} claims {size} bytes; only {} remain (a \
                 truncated file?)",
                b.len().saturating_sub(start)
            ),
        )
    })?;
    let padded = if first == MI_COMPRESSED {
        size
    } else {
        size.div_ceil(8).saturating_mul(8)
    };
    Ok(Element {
        ty: first,
        data,
        next: start.saturating_add(padded),
    })
}

/// Bytes per value of a numeric storage type, `None` for other types.
fn type_size(ty: u32) -> Option<usize> {
    Some(match ty {
        1 | 2 => 1,
        3 | 4 => 2,
        5..=7 => 4,
        9 | 12 | 13 => 8,
        _ => return None,
    })
}

/// Decodes numeric data of storage type `ty` into `f64`.
fn decode(ty: u32, d: &[u8], e: Endian) -> Vec<f64> {
    macro_rules! conv {
        ($t:ty, $n:expr) => {
            d.chunks_exact($n)
                .map(|c| {
                    let mut a = [0u8; $n];
                    a.copy_from_slice(c);
                    (if e.little {
                        <$t>::from_le_bytes(a)
                    } else {
                        <$t>::from_be_bytes(a)
                    }) as f64
                })
                .collect()
        };
    }
    match ty {
        1 => d.iter().map(|&x| f64::from(x as i8)).collect(),
        2 => d.iter().map(|&x| f64::from(x)).collect(),
        3 => conv!(i16, 2),
        4 => conv!(u16, 2),
        5 => conv!(i32, 4),
        6 => conv!(u32, 4),
        7 => conv!(f32, 4),
        9 => conv!(f64, 8),
        12 => conv!(i64, 8),
        _ => conv!(u64, 8),
    }
}

fn class_kind(class: u32) -> &'static str {
    match class {
        1 => "cell",
        2 => "struct",
        3 => "object",
        4 => "char",
        5 => "sparse",
        16 => "function handle",
        17 => "object",
        _ => "unknown class",
    }
}

/// The name text of an `miINT8`/`miUTF8` element.
fn name_of(el: &Element<'_>) -> String {
    String::from_utf8_lossy(el.data)
        .trim_end_matches('\0')
        .to_string()
}

/// Parses the content of one `miMATRIX` element.
fn matrix(file: &str, b: &[u8], at: usize, e: Endian) -> Result<MatVar, FrfError> {
    let place = format!("variable at byte {at}");
    let flags = element(file, &place, b, 0, e)?;
    if flags.ty != MI_UINT32 || flags.data.len() != 8 {
        return Err(bad(
            file,
            &place,
            "the array flags (8 bytes of type miUINT32) are missing",
        ));
    }
    let f = e.u32(&flags.data[0..4]);
    let class = f & 0xff;
    let complex = f & 0x0800 != 0;
    let logical = f & 0x0200 != 0;
    if class == 17 {
        // Opaque (MCOS) objects: the name comes right after the flags.
        let name = element(file, &place, b, flags.next, e)?;
        return Ok(MatVar {
            name: name_of(&name),
            value: MatValue::Other("object"),
        });
    }
    let dims_el = element(file, &place, b, flags.next, e)?;
    let name_el = element(file, &place, b, dims_el.next, e)?;
    let name = name_of(&name_el);
    let place = if name.is_empty() {
        place
    } else {
        format!("variable `{name}`")
    };
    if dims_el.ty != MI_INT32 || dims_el.data.len() < 8 || dims_el.data.len() % 4 != 0 {
        return Err(bad(
            file,
            &place,
            "the dimensions (at least two miINT32 values) are missing",
        ));
    }
    let mut dims = Vec::with_capacity(dims_el.data.len() / 4);
    for c in dims_el.data.chunks_exact(4) {
        let d = e.u32(c) as i32;
        if d < 0 {
            return Err(bad(file, &place, format!("negative dimension {d}")));
        }
        dims.push(d as usize);
    }
    if !(6..=15).contains(&class) {
        return Ok(MatVar {
            name,
            value: MatValue::Other(class_kind(class)),
        });
    }
    if logical {
        return Ok(MatVar {
            name,
            value: MatValue::Other("logical"),
        });
    }
    let count = dims
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| bad(file, &place, format!("dimensions {dims:?} overflow")))?;
    let part = |pos: usize, which: &str| -> Result<(Vec<f64>, usize), FrfError> {
        let el = element(file, &place, b, pos, e)?;
        let Some(size) = type_size(el.ty) else {
            return Err(bad(
                file,
                &place,
                format!(
                    "the {which} part has storage type {}, not a numeric one",
                    el.ty
                ),
            ));
        };
        if el.data.len() != count.saturating_mul(size) {
            return Err(bad(
                file,
                &place,
                format!(
                    "the {which} part holds {} bytes; dimensions {dims:?} of storage type {} \
                     need {}",
                    el.data.len(),
                    el.ty,
                    count.saturating_mul(size)
                ),
            ));
        }
        Ok((decode(el.ty, el.data, e), el.next))
    };
    let (real, next) = part(name_el.next, "real")?;
    let imag = if complex {
        Some(part(next, "imaginary")?.0)
    } else {
        None
    };
    Ok(MatVar {
        name,
        value: MatValue::Numeric { dims, real, imag },
    })
}

/// Inflates an `miCOMPRESSED` element: only as many bytes as the inner element's tag
/// announces are produced (the output never exceeds what the stream really holds).
fn inflate(file: &str, data: &[u8], at: usize, e: Endian) -> Result<Vec<u8>, FrfError> {
    use miniz_oxide::inflate::{decompress_to_vec_zlib_with_limit, TINFLStatus};
    let place = format!("compressed variable at byte {at}");
    let corrupt = |why: String| {
        bad(
            file,
            &place,
            format!("corrupt compressed data ({why}); the file is damaged or truncated"),
        )
    };
    // The first 8 bytes: the tag of the inner element.
    let tag = match decompress_to_vec_zlib_with_limit(data, 8) {
        Ok(v) => v,
        Err(err) if err.status == TINFLStatus::HasMoreOutput => err.output,
        Err(err) => return Err(corrupt(format!("{:?}", err.status))),
    };
    if tag.len() < 8 {
        return Err(corrupt("it holds no complete data element".into()));
    }
    let size = e.u32(&tag[4..8]) as usize;
    let want = size.saturating_add(8);
    match decompress_to_vec_zlib_with_limit(data, want) {
        Ok(v) => Ok(v),
        // More output than the element needs (padding): the element itself is complete.
        Err(err) if err.status == TINFLStatus::HasMoreOutput && err.output.len() >= want => {
            Ok(err.output)
        }
        Err(err) => Err(corrupt(format!("{:?}", err.status))),
    }
}

/// Parses the bytes of a MAT-file; `file` names it in errors ([`FrfError::Format`] with
/// [`FormatProblem::BadRecord`] and the variable or byte offset as the column).
pub fn parse_mat5(bytes: &[u8], file: &str) -> Result<Vec<MatVar>, FrfError> {
    if bytes.len() >= 8 && &bytes[0..8] == b"\x89HDF\r\n\x1a\n"
        || bytes.get(512..520) == Some(&b"\x89HDF\r\n\x1a\n"[..])
        || bytes.starts_with(b"MATLAB 7.3")
    {
        return Err(bad(
            file,
            "header",
            "this is a MATLAB v7.3 (HDF5) .mat file, which is not supported: save it in MATLAB \
             with save(FILE, ..., '-v7')",
        ));
    }
    if bytes.len() < 128 {
        return Err(bad(
            file,
            "header",
            "too short for a MATLAB .mat file (no 128-byte header)",
        ));
    }
    let e = match &bytes[126..128] {
        b"IM" => Endian { little: true },
        b"MI" => Endian { little: false },
        _ => {
            return Err(bad(
                file,
                "header",
                "not a MATLAB level-5 .mat file (no `IM`/`MI` endian indicator at byte 126; a \
                 v4 file?): save it in MATLAB with save(FILE, ..., '-v7')",
            ))
        }
    };
    let mut vars = Vec::new();
    let mut pos = 128;
    while pos < bytes.len() {
        if bytes.len() - pos < 8 && bytes[pos..].iter().all(|&b| b == 0) {
            break;
        }
        let place = format!("byte {pos}");
        let el = element(file, &place, bytes, pos, e)?;
        match el.ty {
            MI_MATRIX => vars.push(matrix(file, el.data, pos, e)?),
            MI_COMPRESSED => {
                let inner = inflate(file, el.data, pos, e)?;
                let iel = element(file, &place, &inner, 0, e)?;
                if iel.ty == MI_MATRIX {
                    vars.push(matrix(file, iel.data, pos, e)?);
                }
            }
            _ => {}
        }
        pos = el.next;
    }
    Ok(vars)
}

/// `x` in the byte order of the file.
fn u32_bytes(x: u32, little: bool) -> [u8; 4] {
    if little {
        x.to_le_bytes()
    } else {
        x.to_be_bytes()
    }
}

/// Appends one element (tag, data, padding to 8 bytes) to `out`.
fn put_element(out: &mut Vec<u8>, ty: u32, data: &[u8], little: bool) {
    out.extend_from_slice(&u32_bytes(ty, little));
    out.extend_from_slice(&u32_bytes(data.len() as u32, little));
    out.extend_from_slice(data);
    out.resize(out.len().div_ceil(8) * 8, 0);
}

/// A numeric double array to write: name, dimensions, real and optional imaginary part
/// (column-major).
pub struct MatWrite<'a> {
    /// Variable name (a MATLAB identifier).
    pub name: &'a str,
    /// Dimensions.
    pub dims: &'a [usize],
    /// Real part.
    pub real: &'a [f64],
    /// Imaginary part (a complex array).
    pub imag: Option<&'a [f64]>,
}

/// The bytes of a little-endian, uncompressed level-5 MAT-file holding `vars` as double
/// arrays (MATLAB `load`, SciPy `loadmat` and [`parse_mat5`] read it).
pub fn mat5_bytes(vars: &[MatWrite<'_>]) -> Vec<u8> {
    mat5_bytes_in(vars, true)
}

/// [`mat5_bytes`] in either byte order.
fn mat5_bytes_in(vars: &[MatWrite<'_>], little: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let mut text = b"MATLAB 5.0 MAT-file, written by frfit".to_vec();
    text.resize(116, b' ');
    out.extend_from_slice(&text);
    out.extend_from_slice(&[0u8; 8]);
    if little {
        out.extend_from_slice(&0x0100u16.to_le_bytes());
        out.extend_from_slice(b"IM");
    } else {
        out.extend_from_slice(&0x0100u16.to_be_bytes());
        out.extend_from_slice(b"MI");
    }
    let f64_bytes = |x: &f64| {
        if little {
            x.to_le_bytes()
        } else {
            x.to_be_bytes()
        }
    };
    for v in vars {
        let mut body = Vec::new();
        let flags = 6u32 | if v.imag.is_some() { 0x0800 } else { 0 };
        let mut f = u32_bytes(flags, little).to_vec();
        f.extend_from_slice(&[0u8; 4]);
        put_element(&mut body, MI_UINT32, &f, little);
        let dims: Vec<u8> = v
            .dims
            .iter()
            .flat_map(|&d| u32_bytes(d as u32, little))
            .collect();
        put_element(&mut body, MI_INT32, &dims, little);
        put_element(&mut body, MI_INT8, v.name.as_bytes(), little);
        let real: Vec<u8> = v.real.iter().flat_map(f64_bytes).collect();
        put_element(&mut body, MI_DOUBLE, &real, little);
        if let Some(im) = v.imag {
            let im: Vec<u8> = im.iter().flat_map(f64_bytes).collect();
            put_element(&mut body, MI_DOUBLE, &im, little);
        }
        put_element(&mut out, MI_MATRIX, &body, little);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_and_reads_back() {
        let re = [1.0, -2.5, 3.25, 4.0, 5.0, 6.0];
        let im = [0.5, 0.0, -1.0, 1e-300, 7.0, -8.0];
        let bytes = mat5_bytes(&[
            MatWrite {
                name: "G",
                dims: &[1, 2, 3],
                real: &re,
                imag: Some(&im),
            },
            MatWrite {
                name: "freq_hz",
                dims: &[3, 1],
                real: &[1.0, 2.0, 3.0],
                imag: None,
            },
        ]);
        let vars = parse_mat5(&bytes, "m.mat").unwrap();
        assert_eq!(vars.len(), 2);
        assert_eq!(vars[0].name, "G");
        assert_eq!(
            vars[0].value,
            MatValue::Numeric {
                dims: vec![1, 2, 3],
                real: re.to_vec(),
                imag: Some(im.to_vec())
            }
        );
        assert_eq!(vars[1].name, "freq_hz");
    }

    #[test]
    fn compressed_and_big_endian_elements() {
        // An uncompressed file, its variable wrapped in miCOMPRESSED.
        let plain = mat5_bytes(&[MatWrite {
            name: "x",
            dims: &[2, 1],
            real: &[1.5, -3.0],
            imag: None,
        }]);
        let inner = &plain[128..];
        let z = miniz_oxide::deflate::compress_to_vec_zlib(inner, 6);
        let mut file = plain[..128].to_vec();
        file.extend_from_slice(&MI_COMPRESSED.to_le_bytes());
        file.extend_from_slice(&(z.len() as u32).to_le_bytes());
        file.extend_from_slice(&z);
        let vars = parse_mat5(&file, "c.mat").unwrap();
        assert_eq!(
            vars[0].value,
            MatValue::Numeric {
                dims: vec![2, 1],
                real: vec![1.5, -3.0],
                imag: None
            }
        );
        // A corrupt stream is an error naming the variable's byte offset.
        let mut bad_file = file.clone();
        for b in &mut bad_file[140..150] {
            *b ^= 0x5a;
        }
        let e = parse_mat5(&bad_file, "c.mat").unwrap_err();
        assert!(e.to_string().contains("c.mat"), "{e}");
        // Big-endian files read the same numbers.
        let vars = [MatWrite {
            name: "y",
            dims: &[1, 3],
            real: &[1.0, 2.0, -0.125],
            imag: Some(&[0.0, 3.0, 1e10]),
        }];
        let le = parse_mat5(&mat5_bytes_in(&vars, true), "le").unwrap();
        let be = parse_mat5(&mat5_bytes_in(&vars, false), "be").unwrap();
        assert_eq!(le, be);
    }

    #[test]
    fn v73_and_v4_are_refused_with_advice() {
        let mut h = vec![0u8; 600];
        h[..10].copy_from_slice(b"MATLAB 7.3");
        h[512..520].copy_from_slice(b"\x89HDF\r\n\x1a\n");
        let e = parse_mat5(&h, "h.mat").unwrap_err();
        assert!(e.to_string().contains("-v7"), "{e}");
        let e = parse_mat5(&[0u8; 200], "v4.mat").unwrap_err();
        assert!(e.to_string().contains("level-5"), "{e}");
    }
}
