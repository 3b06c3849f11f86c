//! Reading `hter` CSV logs: a header row, then one row per sample; columns are found by name in
//! any order, extra columns are ignored. Every problem is reported on one line with the file,
//! the 1-based line number (the header is line 1) and the column.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use hter::rtd::{T_MAX_C, T_MIN_C};

/// Reads the named columns of a CSV log, in the order asked. Rows must have finite numbers in
/// those columns; an empty cell (a sensor-fault row of `hter log2csv`) is refused with its line.
pub fn read_columns(path: &Path, names: &[&str]) -> Result<Vec<Vec<f64>>> {
    let shown = path.display();
    read_cells(path, names)?
        .into_iter()
        .zip(names)
        .map(|(col, name)| {
            col.into_iter()
                .enumerate()
                .map(|(i, v)| {
                    v.ok_or_else(|| {
                        anyhow!(
                            "'{shown}' line {}, column '{name}': empty (a sensor-fault sample); this command needs \
                             a value in every row, give it a span without faults",
                            i + 2
                        )
                    })
                })
                .collect()
        })
        .collect()
}

/// Like [`read_columns`], but an empty cell is `None` (a sample with no reading: `hter log2csv`
/// leaves `temp_c` empty on a sensor fault). Anything else in a cell must be a finite number.
pub fn read_cells(path: &Path, names: &[&str]) -> Result<Vec<Vec<Option<f64>>>> {
    let shown = path.display();
    let file = open(path)?;
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).flexible(false).trim(csv::Trim::All).from_reader(file);
    let headers = rdr.headers().map_err(|e| anyhow!("'{shown}' line 1: {e}"))?.clone();
    let idx: Vec<usize> = names
        .iter()
        .map(|n| {
            column(path, &headers, n)?.ok_or_else(|| {
                anyhow!(
                    "'{shown}': missing column '{n}' (header has: {})",
                    headers.iter().collect::<Vec<_>>().join(", ")
                )
            })
        })
        .collect::<Result<_>>()?;
    let mut cols = vec![Vec::new(); names.len()];
    for (i, rec) in rdr.records().enumerate() {
        let line = i + 2;
        let rec = rec.map_err(|e| anyhow!("'{shown}' line {line}: {}", first_line(&e.to_string())))?;
        for (c, (&j, name)) in idx.iter().zip(names).enumerate() {
            let cell = rec.get(j).unwrap_or("");
            if cell.is_empty() {
                cols[c].push(None);
                continue;
            }
            let v: f64 = cell
                .parse()
                .map_err(|_| anyhow!("'{shown}' line {line}, column '{name}': '{}' is not a number", clip(cell)))?;
            if !v.is_finite() {
                bail!("'{shown}' line {line}, column '{name}': '{}' is not a finite number", clip(cell));
            }
            cols[c].push(Some(v));
        }
    }
    Ok(cols)
}

/// The text of an optional column, one cell per row (trimmed, `""` when empty), or `None` when
/// the header has no such column. Rows line up with [`read_cells`] of the same file.
pub fn read_text(path: &Path, name: &str) -> Result<Option<Vec<String>>> {
    let shown = path.display();
    let file = open(path)?;
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).flexible(false).trim(csv::Trim::All).from_reader(file);
    let headers = rdr.headers().map_err(|e| anyhow!("'{shown}' line 1: {e}"))?.clone();
    let Some(j) = column(path, &headers, name)? else {
        return Ok(None);
    };
    rdr.records()
        .enumerate()
        .map(|(i, rec)| {
            let rec = rec.map_err(|e| anyhow!("'{shown}' line {}: {}", i + 2, first_line(&e.to_string())))?;
            Ok(rec.get(j).unwrap_or("").to_owned())
        })
        .collect::<Result<Vec<_>>>()
        .map(Some)
}

/// Whether the header of a CSV log has a column `name`.
pub fn has_column(path: &Path, name: &str) -> Result<bool> {
    let shown = path.display();
    let file = open(path)?;
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(file);
    let headers = rdr.headers().map_err(|e| anyhow!("'{shown}' line 1: {e}"))?.clone();
    Ok(column(path, &headers, name)?.is_some())
}

/// The index of the column `name` in `headers`, `None` when there is none. A name the header
/// has twice is refused: which of the two holds the data would be a guess (the first was read
/// silently, so a second `temp_c` of −30 °C, or a copy in °F, left no trace in the record).
fn column(path: &Path, headers: &csv::StringRecord, name: &str) -> Result<Option<usize>> {
    let mut at = headers.iter().enumerate().filter(|(_, h)| *h == name).map(|(i, _)| i + 1);
    match (at.next(), at.next()) {
        (Some(first), Some(second)) => bail!(
            "'{}': column '{name}' appears twice in the header (columns {first} and {second}): which one holds the data is ambiguous",
            path.display()
        ),
        (first, _) => Ok(first.map(|i| i - 1)),
    }
}

/// Checks that times strictly increase; names the first offending line.
pub fn check_increasing(path: &Path, t: &[f64]) -> Result<()> {
    if let Some(i) = t.windows(2).position(|w| w[1] <= w[0]) {
        bail!("'{}' line {}: t_s = {} does not increase (previous {})", path.display(), i + 3, t[i + 1], t[i]);
    }
    Ok(())
}

/// Why `c` is no temperature the carrier's Pt100 can report (IEC 60751, [`T_MIN_C`]…[`T_MAX_C`]):
/// in a log, anything outside that is corruption, not a reading. `None` when it is one.
pub fn outside_pt100(c: f64) -> Option<String> {
    (!(f64::from(T_MIN_C)..=f64::from(T_MAX_C)).contains(&c)).then(|| {
        format!(
            "{} °C is outside what a Pt100 can report (IEC 60751: {T_MIN_C}…{T_MAX_C} °C)",
            crate::sim_cmd::shown(c)
        )
    })
}

/// Opens a log to read; a directory is refused by name (opened, it failed only at the first
/// read, as "line 1: Is a directory").
fn open(path: &Path) -> Result<std::fs::File> {
    let shown = path.display();
    if path.is_dir() {
        bail!("cannot read '{shown}': it is a directory");
    }
    let bytes = std::fs::read(path).with_context(|| format!("cannot read '{shown}'"))?;
    if let Some(line) = blank_line_inside(&bytes) {
        bail!("'{shown}' line {line}: a blank line inside the data; remove it (rows are counted one a line)");
    }
    std::fs::File::open(path).with_context(|| format!("cannot read '{shown}'"))
}

/// The 1-based number of the first blank (or all-blank) line that has a non-blank line after it.
/// Every error names a row by its line, counted as the header's line 1 and one line a row (`i + 2`
/// for the `i`-th row, here and in the commands that check the columns); the CSV reader skips
/// blank lines, so one inside the data shifted every later number by one (`t_s,temp_c`, `0,4`,
/// a blank line, `10,warm` reported "line 3" for the bad row on line 4). Blank lines at the end
/// are harmless and allowed.
fn blank_line_inside(bytes: &[u8]) -> Option<usize> {
    let blank = |l: &[u8]| l.iter().all(u8::is_ascii_whitespace);
    let mut first_blank = None;
    for (i, l) in bytes.split(|&b| b == b'\n').enumerate() {
        if !blank(l) {
            if first_blank.is_some() {
                return first_blank;
            }
        } else if first_blank.is_none() {
            first_blank = Some(i + 1);
        }
    }
    None
}

/// Longest cell, in characters, an error message repeats whole.
const CLIP_CHARS: usize = 40;

/// A cell as an error message shows it: whole up to 40 characters, else its start
/// and its length (a corrupt log can hold a megabyte in one cell).
pub fn clip(cell: &str) -> String {
    let n = cell.chars().count();
    if n <= CLIP_CHARS {
        return cell.to_owned();
    }
    format!("{}… ({n} characters)", cell.chars().take(CLIP_CHARS - 8).collect::<String>())
}

fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let p = std::env::temp_dir().join(format!("hter-log-{}-{name}.csv", std::process::id()));
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_directory_is_refused_by_name() {
        let d = std::env::temp_dir();
        let e = read_cells(&d, &["t_s"]).unwrap_err().to_string();
        assert_eq!(e, format!("cannot read '{}': it is a directory", d.display()));
        assert!(has_column(&d, "t_s").is_err() && read_text(&d, "t_s").is_err());
    }

    #[test]
    fn a_long_cell_is_clipped_in_a_message() {
        assert_eq!(clip("4.5x"), "4.5x");
        let long = "9".repeat(2_000_000);
        let p = write("long", &format!("t_s,temp_c\n0,4\n10,{long}x\n"));
        let e = read_columns(&p, &["t_s", "temp_c"]).unwrap_err().to_string();
        assert!(e.len() < 200 && e.contains("… (2000001 characters)"), "{}", &e[..e.len().min(300)]);
    }

    #[test]
    fn reads_by_name_in_any_order() {
        let p = write("ok", "temp_c,x,t_s\n4.0,a,0\n4.5,b,10\n");
        let c = read_columns(&p, &["t_s", "temp_c"]).unwrap();
        assert_eq!(c, vec![vec![0.0, 10.0], vec![4.0, 4.5]]);
    }

    #[test]
    fn errors_name_the_line_and_column() {
        let p = write("bad", "t_s,temp_c\n0,4.0\n10,warm\n");
        let e = read_columns(&p, &["t_s", "temp_c"]).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("temp_c") && e.contains("warm"), "{e}");
        let p = write("nan", "t_s,temp_c\n0,NaN\n");
        let e = read_columns(&p, &["t_s", "temp_c"]).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("finite"), "{e}");
        let p = write("missing", "t_s,duty\n0,1\n");
        let e = read_columns(&p, &["t_s", "temp_c"]).unwrap_err().to_string();
        assert!(e.contains("missing column 'temp_c'"), "{e}");
        let p = write("short", "t_s,temp_c\n0,4.0\n10\n");
        let e = read_columns(&p, &["t_s", "temp_c"]).unwrap_err().to_string();
        assert!(e.contains("line 3"), "{e}");
        assert!(check_increasing(&p, &[0.0, 10.0, 10.0]).unwrap_err().to_string().contains("line 4"));
    }

    #[test]
    fn a_column_named_twice_is_refused() {
        let p = write("dup", "t_s,temp_c,duty,temp_c\n0,4.0,0.5,-30\n10,4.5,0.5,-30\n");
        for e in [
            read_cells(&p, &["t_s", "temp_c"]).unwrap_err(),
            read_text(&p, "temp_c").unwrap_err(),
            has_column(&p, "temp_c").unwrap_err(),
        ] {
            let e = e.to_string();
            assert!(e.contains("column 'temp_c' appears twice in the header (columns 2 and 4)"), "{e}");
        }
        // A column read once is fine beside one that is doubled and not read.
        assert_eq!(read_columns(&p, &["t_s", "duty"]).unwrap(), vec![vec![0.0, 10.0], vec![0.5, 0.5]]);
    }

    #[test]
    fn text_columns_are_optional() {
        let p = write("text", "t_s,temp_c,event\n0,4.0,\n0,4.0,\"set:model=-1.8,0.81;-0.02,-0.01;1\"\n");
        let want = vec![String::new(), "set:model=-1.8,0.81;-0.02,-0.01;1".to_string()];
        assert_eq!(read_text(&p, "event").unwrap(), Some(want));
        assert_eq!(read_text(&p, "mode").unwrap(), None);
    }

    #[test]
    fn empty_cells_are_gaps_or_refused() {
        let p = write("gap", "t_s,temp_c\n0,\n10,4.5\n");
        assert_eq!(
            read_cells(&p, &["t_s", "temp_c"]).unwrap(),
            vec![vec![Some(0.0), Some(10.0)], vec![None, Some(4.5)]]
        );
        let e = read_columns(&p, &["t_s", "temp_c"]).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("'temp_c'") && e.contains("sensor-fault"), "{e}");
        let p = write("gap-nan", "t_s,temp_c\n0,\n10,NaN\n");
        let e = read_cells(&p, &["t_s", "temp_c"]).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("finite"), "{e}");
    }
}
