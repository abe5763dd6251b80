//! INRIA 3DGS PLY: read by property name (any order, extra properties ignored), write with the
//! DLGStream extras (`lang_opacity`, `lang_0..`) when the Gaussians carry language.
//!
//! Read: `binary_little_endian`, `binary_big_endian` and `ascii`; scalar properties of any PLY
//! type; elements other than `vertex` before it must have scalar properties only (they are
//! skipped). Degree is derived from the number of `f_rest_*` (0, 9, 24 or 45).

use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::{sh_coeffs, Gaussians};

const FORMAT: &str = "PLY";

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Encoding {
    Ascii,
    Le,
    Be,
}

#[derive(Clone, Copy, Debug)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    fn read(self, b: &[u8], enc: Encoding) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().expect("sized");
                (if enc == Encoding::Be {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

struct Element {
    name: String,
    count: usize,
    props: Vec<(String, Scalar)>,
}

struct Header {
    enc: Encoding,
    elements: Vec<Element>,
    body_start: usize,
}

fn parse_header(data: &[u8]) -> Result<Header> {
    const MAX_HEADER: usize = 1 << 20;
    let end_marker = b"end_header";
    let search = &data[..data.len().min(MAX_HEADER)];
    let pos = search
        .windows(end_marker.len())
        .position(|w| w == end_marker)
        .ok_or_else(|| Error::foreign(FORMAT, "no end_header within the first 1 MiB"))?;
    let mut body_start = pos + end_marker.len();
    // end_header is followed by "\n" or "\r\n".
    if data.get(body_start) == Some(&b'\r') {
        body_start += 1;
    }
    if data.get(body_start) != Some(&b'\n') {
        return Err(Error::foreign(
            FORMAT,
            "end_header not followed by a newline",
        ));
    }
    body_start += 1;
    let text = std::str::from_utf8(&data[..pos])
        .map_err(|_| Error::foreign(FORMAT, "header is not UTF-8"))?;
    let mut lines = text.lines().map(str::trim);
    if lines.next() != Some("ply") {
        return Err(Error::foreign(FORMAT, "missing 'ply' magic"));
    }
    let mut enc = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, _v] => {
                enc = Some(match *f {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::Le,
                    "binary_big_endian" => Encoding::Be,
                    _ => return Err(Error::foreign(FORMAT, format!("unknown format {f}"))),
                })
            }
            ["element", name, count] => {
                let count: usize = count
                    .parse()
                    .map_err(|_| Error::foreign(FORMAT, format!("bad element count {count}")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", ..] => {
                let e = elements
                    .last()
                    .ok_or_else(|| Error::foreign(FORMAT, "property before element"))?;
                if e.name == "vertex" || elements.iter().all(|x| x.name != "vertex") {
                    return Err(Error::foreign(
                        FORMAT,
                        format!("list property in element '{}' is not supported", e.name),
                    ));
                }
                // list properties after the vertex element are fine: we stop reading there.
                elements
                    .last_mut()
                    .expect("checked")
                    .props
                    .push((String::new(), Scalar::U8));
            }
            ["property", ty, name] => {
                let s = Scalar::parse(ty)
                    .ok_or_else(|| Error::foreign(FORMAT, format!("unknown property type {ty}")))?;
                let e = elements
                    .last_mut()
                    .ok_or_else(|| Error::foreign(FORMAT, "property before element"))?;
                e.props.push((name.to_string(), s));
            }
            _ => {
                return Err(Error::foreign(
                    FORMAT,
                    format!("unrecognised header line '{line}'"),
                ))
            }
        }
    }
    let enc = enc.ok_or_else(|| Error::foreign(FORMAT, "missing format line"))?;
    Ok(Header {
        enc,
        elements,
        body_start,
    })
}

/// Column indices of the attributes we use in the vertex element.
struct Columns {
    pos: [usize; 3],
    scale: [usize; 3],
    rot: [usize; 4],
    opacity: usize,
    dc: [usize; 3],
    rest: Vec<usize>,
    lang_opacity: Option<usize>,
    lang: Vec<usize>,
}

fn columns(props: &[(String, Scalar)]) -> Result<Columns> {
    let find = |n: &str| props.iter().position(|(p, _)| p == n);
    let need = |n: &str| {
        find(n).ok_or_else(|| Error::foreign(FORMAT, format!("missing vertex property '{n}'")))
    };
    let mut rest = Vec::new();
    while let Some(i) = find(&format!("f_rest_{}", rest.len())) {
        rest.push(i);
    }
    if ![0, 9, 24, 45].contains(&rest.len()) {
        return Err(Error::foreign(
            FORMAT,
            format!("{} f_rest properties; expected 0, 9, 24 or 45", rest.len()),
        ));
    }
    let mut lang = Vec::new();
    while let Some(i) = find(&format!("lang_{}", lang.len()))
        .or_else(|| find(&format!("language_feature_{}", lang.len())))
    {
        lang.push(i);
    }
    let lang_opacity = find("lang_opacity").or_else(|| find("opacity_lang"));
    if lang.is_empty() != lang_opacity.is_none() {
        return Err(Error::foreign(
            FORMAT,
            "language features and lang_opacity must come together",
        ));
    }
    Ok(Columns {
        pos: [need("x")?, need("y")?, need("z")?],
        scale: [need("scale_0")?, need("scale_1")?, need("scale_2")?],
        rot: [
            need("rot_0")?,
            need("rot_1")?,
            need("rot_2")?,
            need("rot_3")?,
        ],
        opacity: need("opacity")?,
        dc: [need("f_dc_0")?, need("f_dc_1")?, need("f_dc_2")?],
        rest,
        lang_opacity,
        lang,
    })
}

/// Parse the rows of an element into f64 values. `count` rows are guaranteed present.
fn read_rows(
    data: &[u8],
    at: &mut usize,
    enc: Encoding,
    e: &Element,
    keep: bool,
) -> Result<Vec<f64>> {
    let ncol = e.props.len();
    match enc {
        Encoding::Ascii => {
            let text = std::str::from_utf8(&data[*at..])
                .map_err(|_| Error::foreign(FORMAT, "ASCII body is not UTF-8"))?;
            let mut out = Vec::new();
            let mut consumed = 0;
            for (row, line) in text.split_inclusive('\n').take(e.count).enumerate() {
                consumed += line.len();
                let vals: Vec<f64> = line
                    .split_whitespace()
                    .map(|t| t.parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| {
                        Error::foreign(FORMAT, format!("bad number in {} row {row}", e.name))
                    })?;
                if vals.len() != ncol {
                    return Err(Error::foreign(
                        FORMAT,
                        format!(
                            "{} row {row} has {} values, expected {ncol}",
                            e.name,
                            vals.len()
                        ),
                    ));
                }
                if keep {
                    out.extend(vals);
                }
            }
            if keep && out.len() != e.count * ncol {
                return Err(Error::foreign(
                    FORMAT,
                    format!("{} rows of '{}' declared, fewer present", e.count, e.name),
                ));
            }
            *at += consumed;
            Ok(out)
        }
        Encoding::Le | Encoding::Be => {
            let stride: usize = e.props.iter().map(|(_, s)| s.size()).sum();
            let bytes = e
                .count
                .checked_mul(stride)
                .ok_or_else(|| Error::foreign(FORMAT, "element size overflows"))?;
            if data.len() - *at < bytes {
                return Err(Error::foreign(
                    FORMAT,
                    format!(
                        "{} rows of '{}' need {bytes} bytes, {} present",
                        e.count,
                        e.name,
                        data.len() - *at
                    ),
                ));
            }
            let mut out = Vec::new();
            if keep {
                out.reserve(e.count * ncol);
                let offs: Vec<usize> = e
                    .props
                    .iter()
                    .scan(0, |o, (_, s)| {
                        let r = *o;
                        *o += s.size();
                        Some(r)
                    })
                    .collect();
                for row in data[*at..*at + bytes].chunks_exact(stride) {
                    for (k, (_, s)) in e.props.iter().enumerate() {
                        out.push(s.read(&row[offs[k]..], enc));
                    }
                }
            }
            *at += bytes;
            Ok(out)
        }
    }
}

/// Read an INRIA-style PLY from memory.
/// Read an INRIA-layout PLY (ASCII or binary); at most `limits.max_gaussians` vertices, and
/// the vertex rows' buffer within `limits.max_alloc`.
pub fn read_ply(data: &[u8], limits: &Limits) -> Result<Gaussians> {
    let h = parse_header(data)?;
    let mut at = h.body_start;
    for e in &h.elements {
        if e.name != "vertex" {
            if e.props.iter().any(|(n, _)| n.is_empty()) {
                return Err(Error::foreign(
                    FORMAT,
                    format!("element '{}' before vertex has list properties", e.name),
                ));
            }
            read_rows(data, &mut at, h.enc, e, false)?;
            continue;
        }
        let c = columns(&e.props)?;
        let ncol = e.props.len();
        limits.check_gaussians("PLY vertex count", e.count as u64, 0)?;
        limits.check_alloc(
            "PLY vertex rows",
            (e.count as u64).saturating_mul(ncol as u64 * 8),
            0,
        )?;
        // Binary: checked in read_rows before allocation. ASCII needs >= 2 bytes per value.
        if h.enc == Encoding::Ascii
            && e.count.saturating_mul(ncol).saturating_mul(2) > data.len() - at
        {
            return Err(Error::foreign(
                FORMAT,
                "vertex count larger than the file can hold",
            ));
        }
        let rows = read_rows(data, &mut at, h.enc, e, true)?;
        let degree = match c.rest.len() {
            0 => 0,
            9 => 1,
            24 => 2,
            _ => 3,
        };
        let mut g = Gaussians::new(degree, c.lang.len());
        let k = sh_coeffs(degree);
        let n = e.count;
        g.positions.reserve(n);
        g.sh.reserve(n * k * 3);
        for r in rows.chunks_exact(ncol) {
            let f = |i: usize| r[i] as f32;
            g.positions.push(c.pos.map(f));
            g.log_scales.push(c.scale.map(f));
            g.rotations.push(c.rot.map(f));
            g.opacity.push(f(c.opacity));
            for coef in 0..k {
                for ch in 0..3 {
                    // INRIA f_rest is channel-major: all of R's coefficients, then G's, then B's.
                    g.sh.push(if coef == 0 {
                        f(c.dc[ch])
                    } else {
                        f(c.rest[ch * (k - 1) + coef - 1])
                    });
                }
            }
            if let Some(lo) = c.lang_opacity {
                g.lang_opacity.push(f(lo));
                g.lang.extend(c.lang.iter().map(|&i| f(i)));
            }
        }
        return Ok(g);
    }
    Err(Error::foreign(FORMAT, "no 'vertex' element"))
}

/// Write binary little-endian INRIA PLY (with normals set to 0, as the INRIA code does).
pub fn write_ply(g: &Gaussians) -> Result<Vec<u8>> {
    g.check_shapes()?;
    let k = g.coeffs();
    let mut hdr = String::from("ply\nformat binary_little_endian 1.0\n");
    hdr += &format!("element vertex {}\n", g.len());
    for p in [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ] {
        hdr += &format!("property float {p}\n");
    }
    for i in 0..(k - 1) * 3 {
        hdr += &format!("property float f_rest_{i}\n");
    }
    hdr += "property float opacity\n";
    for p in [
        "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        hdr += &format!("property float {p}\n");
    }
    if g.has_language() {
        hdr += "property float lang_opacity\n";
        for i in 0..g.lang_width {
            hdr += &format!("property float lang_{i}\n");
        }
    }
    hdr += "end_header\n";
    let floats = 9
        + (k - 1) * 3
        + 8
        + if g.has_language() {
            1 + g.lang_width
        } else {
            0
        };
    let mut out = Vec::with_capacity(hdr.len() + g.len() * floats * 4);
    out.extend_from_slice(hdr.as_bytes());
    let mut put = |v: f32| out.extend_from_slice(&v.to_le_bytes());
    for i in 0..g.len() {
        g.positions[i].iter().for_each(|&v| put(v));
        (0..3).for_each(|_| put(0.0));
        let sh = g.sh_of(i);
        (0..3).for_each(|c| put(sh[c]));
        for c in 0..3 {
            for coef in 1..k {
                put(sh[coef * 3 + c]);
            }
        }
        put(g.opacity[i]);
        g.log_scales[i].iter().for_each(|&v| put(v));
        g.rotations[i].iter().for_each(|&v| put(v));
        if g.has_language() {
            put(g.lang_opacity[i]);
            g.lang_of(i).iter().for_each(|&v| put(v));
        }
    }
    Ok(out)
}
