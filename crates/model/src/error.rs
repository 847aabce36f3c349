//! Errors of model files and data files, located by file, line and column.

use std::fmt;

/// A problem with a model or data file: where it is and what it is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ModelError {
    /// The file.
    pub file: String,
    /// 1-based line, if known.
    pub line: Option<usize>,
    /// 1-based column, if known.
    pub column: Option<usize>,
    /// What is wrong.
    pub message: String,
}

impl ModelError {
    /// An error about a whole file.
    pub fn file(file: &str, message: impl Into<String>) -> Self {
        Self { file: file.into(), line: None, column: None, message: message.into() }
    }

    /// An error at a byte offset of the file's text.
    pub fn at(file: &str, text: &str, offset: usize, message: impl Into<String>) -> Self {
        let (line, column) = line_column(text, offset);
        Self { file: file.into(), line: Some(line), column: Some(column), message: message.into() }
    }
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(column) = self.column {
                write!(f, ":{column}")?;
            }
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for ModelError {}

/// Where the lines of a model file's text come from when another format was written as one
/// (a PEtab problem): an error located in the text is reported where the user wrote what it
/// is about. Empty for a model file someone wrote.
#[derive(Clone, Debug, Default)]
pub struct SourceMap {
    /// The text's file name, as its errors carry it.
    pub file: String,
    /// (line, first column, origin), in the order written: an error at `line` and a column
    /// at or after the first column belongs to the last such entry. The origin's file, line
    /// and column replace the error's, and its message is put before the error's.
    pub origins: Vec<(usize, usize, ModelError)>,
}

impl SourceMap {
    /// A map of the text called `file`.
    pub fn new(file: impl Into<String>) -> Self {
        Self { file: file.into(), origins: Vec::new() }
    }

    /// Records that line `line` of the text, from column `column` on, comes from `origin`.
    pub fn record(&mut self, line: usize, column: usize, origin: ModelError) {
        self.origins.push((line, column, origin));
    }

    /// `e` located where its subject was written, if it is located in the text and the map
    /// knows that line; otherwise `e` itself.
    pub fn locate(&self, e: ModelError) -> ModelError {
        self.find(&e).unwrap_or(e)
    }

    /// `e` located where its subject was written, if it is located in the text and the map
    /// knows that line.
    pub fn find(&self, e: &ModelError) -> Option<ModelError> {
        let (Some(line), true) = (e.line, e.file == self.file) else { return None };
        let column = e.column.unwrap_or(1);
        let (_, _, at) = self
            .origins
            .iter()
            .rfind(|(l, c, _)| *l == line && *c <= column)
            .or_else(|| self.origins.iter().find(|(l, _, _)| *l == line))?;
        Some(ModelError {
            file: at.file.clone(),
            line: at.line,
            column: at.column,
            message: format!("{}{}", at.message, e.message),
        })
    }
}

/// 1-based line and column (in characters) of a byte offset.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// The byte offset of character `chars` into the string starting at byte `start` of `text`.
pub fn char_offset(text: &str, start: usize, chars: usize) -> usize {
    text[start..].char_indices().nth(chars).map_or(text.len(), |(i, _)| start + i)
}
