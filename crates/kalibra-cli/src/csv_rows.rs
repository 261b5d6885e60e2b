//! The CSV reading both `kalibra eval` and `kalibra tune` share: a header, then rows of the
//! header's length, with errors that name the file, the row (the header is row 1) and the
//! column.

use std::fmt::Display;

/// A CSV file's header and a reader positioned after it.
pub struct Rows<'a, N: Display> {
    /// The file, as errors name it.
    name: N,
    reader: csv::Reader<&'a [u8]>,
    /// The header's cells, trimmed.
    pub header: csv::StringRecord,
}

impl<'a, N: Display> Rows<'a, N> {
    /// Reads the header of `bytes` (from the file `name`).
    pub fn new(name: N, bytes: &'a [u8]) -> Result<Self, String> {
        let mut reader = csv::ReaderBuilder::new()
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(bytes);
        let header = reader
            .headers()
            .map_err(|e| format!("{name}: row 1: cannot read the header: {e}"))?
            .clone();
        Ok(Self {
            name,
            reader,
            header,
        })
    }

    /// Reads the next row into `record` and returns its row number, `None` at the end. A row
    /// whose length differs from the header's is an error (a ragged or truncated file).
    pub fn next_row(&mut self, record: &mut csv::StringRecord) -> Result<Option<u64>, String> {
        let name = &self.name;
        match self.reader.read_record(record) {
            Ok(false) => return Ok(None),
            Ok(true) => {}
            Err(e) => {
                let row = e
                    .position()
                    .map(|p| format!("row {}: ", p.line()))
                    .unwrap_or_default();
                return Err(format!("{name}: {row}cannot read the file: {e}"));
            }
        }
        let line = record.position().map_or(0, |p| p.line());
        if record.len() != self.header.len() {
            return Err(format!(
                "{name}: row {line}: {} fields, but the header has {} (a ragged row{})",
                record.len(),
                self.header.len(),
                if record.len() < self.header.len() {
                    "; is the file truncated?"
                } else {
                    ""
                }
            ));
        }
        Ok(Some(line))
    }

    /// An error about the cell in row `line` and column `c` (from 0).
    pub fn cell_error(&self, line: u64, c: usize, msg: String) -> String {
        format!(
            "{}: row {line}, column {} ({}): {msg}",
            self.name,
            c + 1,
            &self.header[c]
        )
    }
}
