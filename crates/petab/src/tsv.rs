//! PEtab's tab-separated tables, every cell with its line and column for errors.

use std::path::Path;

use sysid_model::ModelError;

/// One row: its line in the file, its cells and the 1-based column where each starts.
#[derive(Clone, Debug)]
pub struct Row {
    line: usize,
    cells: Vec<String>,
    starts: Vec<usize>,
}

/// A table read from a TSV file.
#[derive(Clone, Debug)]
pub struct Tsv {
    /// The file, as named in errors.
    pub file: String,
    headers: Vec<String>,
    /// The data rows (blank lines skipped).
    pub rows: Vec<Row>,
}

/// A cell of a table: its text and where it is.
#[derive(Clone, Copy, Debug)]
pub struct Cell<'a> {
    /// The text, trimmed; empty when the row has no such cell.
    pub text: &'a str,
    table: &'a Tsv,
    row: &'a Row,
    column: usize,
}

impl<'a> Cell<'a> {
    /// An error at this cell.
    pub fn err(&self, message: impl Into<String>) -> ModelError {
        ModelError {
            file: self.table.file.clone(),
            line: Some(self.row.line),
            column: self.row.starts.get(self.column).copied().or(Some(1)),
            message: format!("column `{}`: {}", self.table.headers[self.column], message.into()),
        }
    }

    /// Whether the cell is empty or `nan` (PEtab's "not given").
    pub fn is_blank(&self) -> bool {
        self.text.is_empty() || self.text.eq_ignore_ascii_case("nan")
    }

    /// The cell as a number (`inf`, `-inf` included), or an error naming it.
    pub fn number(&self) -> Result<f64, ModelError> {
        parse_number(self.text).ok_or_else(|| match self.text.trim().parse::<f64>() {
            Ok(v) if v.is_infinite() => self.err(format!(
                "`{}` is beyond the largest number (1.8e308); write inf for infinity",
                self.text
            )),
            _ => self.err(format!("`{}` is not a number", self.text)),
        })
    }

    /// The cell as an id (PEtab's `^[a-zA-Z_]\w*$`), or an error naming `what` it is.
    pub fn id(&self, what: &str) -> Result<&'a str, ModelError> {
        let mut chars = self.text.chars();
        let valid = chars.next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && chars.all(|c| c.is_ascii_alphanumeric() || c == '_');
        match valid {
            true => Ok(self.text),
            false if self.text.is_empty() => Err(self.err(format!("a {what} needs an id"))),
            false => Err(self.err(format!(
                "`{}` is not a valid {what} id: letters, digits and _, not starting with a digit",
                self.text
            ))),
        }
    }
}

/// A PEtab number: a float, or `inf` / `-inf` in any case.
pub fn parse_number(text: &str) -> Option<f64> {
    let t = text.trim();
    match t.to_ascii_lowercase().as_str() {
        "inf" | "+inf" | "infinity" => Some(f64::INFINITY),
        "-inf" | "-infinity" => Some(f64::NEG_INFINITY),
        "nan" => None,
        // A finite literal that overflows (1e400) is no number: inf is written as such.
        _ => t.parse::<f64>().ok().filter(|v| v.is_finite()),
    }
}

impl Tsv {
    /// Reads a TSV file.
    pub fn read(path: &Path) -> Result<Self, ModelError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| ModelError::file(&file, format!("cannot be read: {e}")))?;
        Self::parse(&text, &file)
    }

    /// Reads TSV text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, ModelError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let Some((_, header)) = lines.next() else {
            return Err(ModelError::file(file, "the table is empty: it needs a header row"));
        };
        let (headers, _) = split(header);
        for (i, h) in headers.iter().enumerate() {
            if headers[..i].contains(h) {
                return Err(ModelError {
                    file: file.to_string(),
                    line: Some(1),
                    column: None,
                    message: format!("column `{h}` is given twice"),
                });
            }
        }
        let mut rows = Vec::new();
        for (i, l) in lines {
            let (cells, starts) = split(l);
            // Trailing empty cells are tolerated (editors leave them); a value beyond the
            // header has no column to belong to.
            if let Some(extra) = (headers.len()..cells.len()).find(|&c| !cells[c].is_empty()) {
                return Err(ModelError {
                    file: file.to_string(),
                    line: Some(i + 1),
                    column: Some(starts[extra]),
                    message: format!(
                        "this row has {} cells and the header {} columns: `{}` belongs to no column",
                        cells.len(),
                        headers.len(),
                        cells[extra]
                    ),
                });
            }
            rows.push(Row { line: i + 1, cells, starts });
        }
        Ok(Self { file: file.to_string(), headers, rows })
    }

    /// The index of column `name`.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.headers.iter().position(|h| h == name)
    }

    /// The index of column `name`, or an error naming the table's columns.
    pub fn required(&self, name: &str) -> Result<usize, ModelError> {
        self.column(name).ok_or_else(|| ModelError {
            file: self.file.clone(),
            line: Some(1),
            column: None,
            message: format!("no column `{name}` (columns: {})", self.headers.join(", ")),
        })
    }

    /// The line of row `row` in the file.
    pub fn line(&self, row: usize) -> usize {
        self.rows[row].line
    }

    /// The column names.
    pub fn headers(&self) -> &[String] {
        &self.headers
    }

    /// The cell of row `row` in column `column` (empty when the row is short).
    pub fn cell(&self, row: usize, column: usize) -> Cell<'_> {
        let r = &self.rows[row];
        Cell { text: r.cells.get(column).map_or("", |c| c.as_str()), table: self, row: r, column }
    }

    /// The cell in column `name`, if the table has it.
    pub fn cell_named(&self, row: usize, name: &str) -> Option<Cell<'_>> {
        self.column(name).map(|c| self.cell(row, c))
    }
}

/// A line's cells, trimmed and unquoted, with the 1-based character column of each.
fn split(line: &str) -> (Vec<String>, Vec<usize>) {
    let line = line.strip_suffix('\r').unwrap_or(line);
    let mut cells = Vec::new();
    let mut starts = Vec::new();
    let mut column = 1;
    for raw in line.split('\t') {
        let trimmed = raw.trim();
        let lead = raw.chars().take_while(|c| c.is_whitespace()).count();
        starts.push(column + lead);
        let unquoted =
            trimmed.strip_prefix('"').and_then(|s| s.strip_suffix('"')).unwrap_or(trimmed);
        cells.push(unquoted.to_string());
        column += raw.chars().count() + 1;
    }
    (cells, starts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_know_their_line_and_column() {
        let t = Tsv::parse("a\tb\n\n1\t x\n", "f.tsv").expect("reads");
        let c = t.cell(0, 1);
        assert_eq!(c.text, "x");
        let e = c.number().unwrap_err();
        assert_eq!((e.line, e.column), (Some(3), Some(4)));
        assert!(e.to_string().starts_with("f.tsv:3:4: column `b`: `x` is not a number"), "{e}");
        assert_eq!(parse_number("-Inf"), Some(f64::NEG_INFINITY));
    }

    #[test]
    fn a_value_beyond_the_header_is_refused_where_it_is() {
        let e = Tsv::parse("a\tb\n1\t2\t3\n", "f.tsv").unwrap_err();
        assert_eq!((e.line, e.column), (Some(2), Some(5)));
        assert!(e.message.contains("`3` belongs to no column"), "{e}");
        assert!(Tsv::parse("a\tb\n1\t2\t\n", "f.tsv").is_ok());
    }
}
