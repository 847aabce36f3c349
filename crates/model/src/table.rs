//! Numeric CSV tables: a header row, time in the first column, one column per quantity.
//! Empty cells are missing values. Every error names the file, the line and the column.

use std::fmt;
use std::path::Path;

/// A CSV table read into columns.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    source: String,
    headers: Vec<String>,
    time: Vec<f64>,
    /// The file line of each row.
    lines: Vec<u64>,
    /// Columns after the time column; `None` for an empty cell.
    columns: Vec<Vec<Option<f64>>>,
}

/// A table that cannot be read, located as precisely as possible.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TableError {
    /// The file (or a description of the text).
    pub source: String,
    /// 1-based line number, if the error is on a line.
    pub line: Option<u64>,
    /// 1-based character position of the cell on its line, if the error is in a cell.
    pub position: Option<usize>,
    /// The column, if the error is in one.
    pub column: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.source)?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(position) = self.position {
                write!(f, ":{position}")?;
            }
        }
        if let Some(column) = &self.column {
            write!(f, ": column `{column}`")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for TableError {}

impl Table {
    /// Reads a CSV file.
    pub fn read(path: &Path) -> Result<Self, TableError> {
        let source = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| TableError {
            source: source.clone(),
            line: None,
            position: None,
            column: None,
            message: e.to_string(),
        })?;
        Self::parse(&text, &source)
    }

    /// Parses CSV text; `source` names it in errors. A leading byte-order mark is skipped.
    pub fn parse(text: &str, source: &str) -> Result<Self, TableError> {
        let text = without_bom(text);
        let err = |line: Option<u64>, column: Option<&str>, message: String| TableError {
            source: source.to_string(),
            line,
            position: None,
            column: column.map(str::to_string),
            message,
        };
        // The same, at the cell of field `c` on `line`.
        let at_cell = |line: Option<u64>, c: usize, column: &str, message: String| TableError {
            position: line.and_then(|l| cell_position(text, l, c)),
            ..err(line, Some(column), message)
        };
        let mut reader =
            csv::ReaderBuilder::new().trim(csv::Trim::All).from_reader(text.as_bytes());
        let headers: Vec<String> = reader
            .headers()
            .map_err(|e| err(Some(1), None, e.to_string()))?
            .iter()
            .map(str::to_string)
            .collect();
        if headers.is_empty() || headers.iter().all(String::is_empty) {
            return Err(err(Some(1), None, "no header row".into()));
        }
        for (i, h) in headers.iter().enumerate() {
            if h.is_empty() {
                return Err(err(Some(1), None, format!("column {} has no name", i + 1)));
            }
            if headers[..i].contains(h) {
                return Err(err(Some(1), Some(h), "the name is used twice".into()));
            }
        }
        let mut time = Vec::new();
        let mut lines = Vec::new();
        let mut columns = vec![Vec::new(); headers.len() - 1];
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map(|p| p.line());
                err(line, None, e.to_string().split(": ").last().unwrap_or_default().to_string())
            })?;
            let line = record.position().map(|p| p.line());
            if record.iter().all(str::is_empty) {
                continue;
            }
            for (c, cell) in record.iter().enumerate() {
                let value = if cell.is_empty() {
                    None
                } else {
                    let v: f64 = cell.parse().map_err(|_| {
                        at_cell(line, c, &headers[c], format!("`{cell}` is not a number"))
                    })?;
                    if !v.is_finite() {
                        return Err(at_cell(
                            line,
                            c,
                            &headers[c],
                            format!("`{cell}` is not a finite number"),
                        ));
                    }
                    Some(v)
                };
                if c == 0 {
                    let t = value.ok_or_else(|| {
                        at_cell(line, 0, &headers[0], "the time is missing".into())
                    })?;
                    if let Some(&previous) = time.last()
                        && t <= previous
                    {
                        let what = if t < previous { "goes back" } else { "is repeated" };
                        return Err(at_cell(
                            line,
                            0,
                            &headers[0],
                            format!("time {t} {what} (previous {previous})"),
                        ));
                    }
                    time.push(t);
                    lines.push(line.unwrap_or(0));
                } else {
                    columns[c - 1].push(value);
                }
            }
        }
        if time.is_empty() {
            return Err(err(None, None, "no data rows".into()));
        }
        Ok(Self { source: source.to_string(), headers, time, lines, columns })
    }

    /// A table built in memory (an imported problem's measurements): `rows` of a time and
    /// one cell per column after it, sorted here by time (stably). Unlike a CSV file, a time
    /// may repeat: replicates at one time are rows of their own. `source` names the table in
    /// errors; its rows have no file lines.
    pub fn from_rows(
        source: &str,
        headers: Vec<String>,
        mut rows: Vec<(f64, Vec<Option<f64>>)>,
    ) -> Result<Self, TableError> {
        let err = |message: String| TableError {
            source: source.to_string(),
            line: None,
            position: None,
            column: None,
            message,
        };
        if rows.is_empty() {
            return Err(err("no data rows".into()));
        }
        if let Some((t, _)) = rows.iter().find(|(t, cells)| {
            !t.is_finite()
                || cells.len() + 1 != headers.len()
                || cells.iter().flatten().any(|v| !v.is_finite())
        }) {
            return Err(err(format!(
                "a row at time {t} is not finite or has the wrong number of cells"
            )));
        }
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut columns = vec![Vec::with_capacity(rows.len()); headers.len() - 1];
        let mut time = Vec::with_capacity(rows.len());
        for (t, cells) in rows {
            time.push(t);
            for (c, v) in cells.into_iter().enumerate() {
                columns[c].push(v);
            }
        }
        let lines = vec![0; time.len()];
        Ok(Self { source: source.to_string(), headers, time, lines, columns })
    }

    /// The file line of data row `row` (0-based, in time order).
    pub fn line(&self, row: usize) -> Option<u64> {
        self.lines.get(row).copied().filter(|&l| l > 0)
    }

    /// Where the table came from.
    pub fn source(&self) -> &str {
        &self.source
    }
    /// The header of the time column.
    pub fn time_name(&self) -> &str {
        &self.headers[0]
    }
    /// The times (first column).
    pub fn time(&self) -> &[f64] {
        &self.time
    }
    /// Names of the columns after the time column.
    pub fn names(&self) -> &[String] {
        &self.headers[1..]
    }
    /// A column by name (after the time column); `None` cells are missing.
    pub fn column(&self, name: &str) -> Option<&[Option<f64>]> {
        self.names().iter().position(|h| h == name).map(|i| self.columns[i].as_slice())
    }
    /// The present samples of a column as (times, values).
    pub fn samples(&self, name: &str) -> Option<(Vec<f64>, Vec<f64>)> {
        let col = self.column(name)?;
        Some(self.time.iter().zip(col).filter_map(|(&t, v)| v.map(|v| (t, v))).unzip())
    }
}

/// The text without a leading UTF-8 byte-order mark, which some programs write at the start
/// of a file (Excel's "CSV UTF-8", Notepad): it is not part of the first name.
pub fn without_bom(text: &str) -> &str {
    text.strip_prefix('\u{feff}').unwrap_or(text)
}

/// The 1-based character position of field `field` (0-based) on line `line` of `text`:
/// after `field` commas, past leading blanks (a numeric table has no quoted commas).
pub fn cell_position(text: &str, line: u64, field: usize) -> Option<usize> {
    let raw = text.lines().nth(usize::try_from(line).ok()?.checked_sub(1)?)?;
    let mut start = 0;
    for _ in 0..field {
        start += raw[start..].find(',')? + 1;
    }
    let blanks = raw[start..].chars().take_while(|c| c.is_whitespace()).count();
    Some(raw[..start].chars().count() + blanks + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_columns_with_missing_cells() {
        let t = Table::parse("t, y, v\n0, 1.5, \n1, , 2e-1\n2, 3, 4\n", "mem").unwrap();
        assert_eq!(t.names(), ["y", "v"]);
        assert_eq!(t.samples("y").unwrap(), (vec![0.0, 2.0], vec![1.5, 3.0]));
        assert_eq!(t.samples("v").unwrap(), (vec![1.0, 2.0], vec![0.2, 4.0]));
        assert_eq!(t.column("z"), None);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let e = |text: &str| Table::parse(text, "data.csv").unwrap_err().to_string();
        assert_eq!(e("t,y\n0,1\n1,abc\n"), "data.csv:3:3: column `y`: `abc` is not a number");
        assert_eq!(
            e("t, y\n0, 1\n1,  NaN\n"),
            "data.csv:3:5: column `y`: `NaN` is not a finite number"
        );
        assert_eq!(
            e("t,y\n0,1\n1,1e400\n"),
            "data.csv:3:3: column `y`: `1e400` is not a finite number"
        );
        assert_eq!(
            e("t,y\n0,1\n0,2\n"),
            "data.csv:3:1: column `t`: time 0 is repeated (previous 0)"
        );
        assert_eq!(e("t,y\n1,1\n0,2\n"), "data.csv:3:1: column `t`: time 0 goes back (previous 1)");
        assert_eq!(e("t,y\n0,1\n,2\n"), "data.csv:3:1: column `t`: the time is missing");
        assert_eq!(e("t,y,y\n0,1,2\n"), "data.csv:1: column `y`: the name is used twice");
        assert_eq!(e("t,y\n"), "data.csv: no data rows");
        assert!(e("t,y\n0,1\n1,2,3\n").starts_with("data.csv:3: "), "{}", e("t,y\n0,1\n1,2,3\n"));
    }

    #[test]
    fn a_leading_byte_order_mark_is_skipped() {
        let t = Table::parse("\u{feff}t, y\n0, 1.5\n1, 2\n", "mem").unwrap();
        assert_eq!((t.time_name(), t.names()), ("t", &["y".to_string()][..]));
        assert_eq!(t.samples("y").unwrap(), (vec![0.0, 1.0], vec![1.5, 2.0]));
        let e = Table::parse("\u{feff}t,y\n0,1\n1,abc\n", "data.csv").unwrap_err();
        assert_eq!(e.to_string(), "data.csv:3:3: column `y`: `abc` is not a number");
    }
}
