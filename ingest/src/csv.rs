//! `compression_info.csv` as pandas writes it: header `,min,max,file`, one row per attribute,
//! `min`/`max` empty for attributes stored without normalisation. Values are kept as the f64
//! pandas' `read_csv` gives (the reference's decoder computes with those).

use crate::IngestError;

#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub name: String,
    /// `(min, max)`, or `None` when both cells are empty.
    pub range: Option<(f64, f64)>,
    pub file: String,
}

pub fn parse(text: &str, what: &str) -> Result<Vec<Row>, IngestError> {
    let mut lines = text.lines();
    let header = lines
        .next()
        .ok_or_else(|| IngestError::format(what, "empty file"))?;
    if header.trim_end() != ",min,max,file" {
        return Err(IngestError::format(
            what,
            format!("header {header:?}, expected \",min,max,file\""),
        ));
    }
    let mut rows = Vec::new();
    for (i, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.trim_end().split(',').collect();
        if cells.len() != 4 {
            return Err(IngestError::format(
                what,
                format!("line {}: {} cells, expected 4", i + 2, cells.len()),
            ));
        }
        let num = |s: &str| -> Result<Option<f64>, IngestError> {
            if s.is_empty() {
                return Ok(None);
            }
            s.parse::<f64>().map(Some).map_err(|_| {
                IngestError::format(what, format!("line {}: {s:?} is not a number", i + 2))
            })
        };
        let range = match (num(cells[1])?, num(cells[2])?) {
            (Some(lo), Some(hi)) => Some((lo, hi)),
            (None, None) => None,
            _ => {
                return Err(IngestError::format(
                    what,
                    format!("line {}: only one of min/max", i + 2),
                ))
            }
        };
        if let Some((lo, hi)) = range {
            if !lo.is_finite() || !hi.is_finite() {
                return Err(IngestError::format(
                    what,
                    format!("line {}: range is not finite", i + 2),
                ));
            }
        }
        rows.push(Row {
            name: cells[0].to_string(),
            range,
            file: cells[3].to_string(),
        });
    }
    Ok(rows)
}

pub fn find<'a>(rows: &'a [Row], name: &str) -> Option<&'a Row> {
    rows.iter().find(|r| r.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_pandas_output() {
        let t = ",min,max,file\n_xyz,-2.2021565,1.0021952,_xyz.jxl\n_scaling,,,_scaling.jxl\n";
        let r = parse(t, "csv").unwrap();
        assert_eq!(r[0].range, Some((-2.2021565, 1.0021952)));
        assert_eq!(r[1].range, None);
        assert_eq!(find(&r, "_scaling").unwrap().file, "_scaling.jxl");
        assert!(parse("min,max\n", "csv").is_err());
        assert!(parse(",min,max,file\n_x,1,,f\n", "csv").is_err());
        assert!(parse(",min,max,file\n_x,nan,1,f\n", "csv").is_err());
    }
}
