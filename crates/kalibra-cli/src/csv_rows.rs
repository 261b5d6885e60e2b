//! The CSV reading both `kalibra eval` and `kalibra tune` share: a header, then rows of the
//! header's length, with errors that name the file, the row (the header is row 1) and the
//! column.

use std::fmt::Display;
use std::io::Read;

/// A CSV file's header and a reader positioned after it, over any byte source (a file read
/// as it goes, or bytes in memory).
pub struct Rows<N: Display, R: Read> {
    /// The file, as errors name it.
    name: N,
    reader: csv::Reader<R>,
    /// The header's cells, trimmed.
    pub header: csv::StringRecord,
    /// The row number of the source's first line, less 1 (0 when the source holds the header).
    offset: u64,
}

impl<N: Display, R: Read> Rows<N, R> {
    /// Reads the header of `source` (the file `name`).
    pub fn new(name: N, source: R) -> Result<Self, String> {
        let mut reader = csv::ReaderBuilder::new()
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(source);
        let header = reader
            .headers()
            .map_err(|e| format!("{name}: row 1: cannot read the header: {e}"))?
            .clone();
        Ok(Self {
            name,
            reader,
            header,
            offset: 0,
        })
    }

    /// Rows of `source`, a later piece of the file `name` whose header is `header`; the
    /// piece's first line is row `first_row` of the file, and starts a record. Fields are
    /// not trimmed: the caller trims the fields it reads (trimming every field of a byte
    /// record copies the record).
    pub fn continuing(name: N, source: R, header: csv::StringRecord, first_row: u64) -> Self {
        let reader = csv::ReaderBuilder::new()
            .flexible(true)
            .has_headers(false)
            .from_reader(source);
        Self {
            name,
            reader,
            header,
            offset: first_row - 1,
        }
    }

    /// Reads the next row into `record` and returns its row number, `None` at the end. A row
    /// whose length differs from the header's is an error (a ragged or truncated file).
    pub fn next_row(&mut self, record: &mut csv::StringRecord) -> Result<Option<u64>, String> {
        let read = self.reader.read_record(record);
        let line = self.offset + record.position().map_or(0, |p| p.line());
        self.checked(read, line, record.len())
    }

    /// As [`Rows::next_row`], into a byte record: no UTF-8 check of every cell, for the large
    /// logs where that check costs (numbers are ASCII; a cell that is not is reported when
    /// parsed).
    pub fn next_byte_row(&mut self, record: &mut csv::ByteRecord) -> Result<Option<u64>, String> {
        let read = self.reader.read_byte_record(record);
        let line = self.offset + record.position().map_or(0, |p| p.line());
        self.checked(read, line, record.len())
    }

    fn checked(
        &self,
        read: csv::Result<bool>,
        line: u64,
        fields: usize,
    ) -> Result<Option<u64>, String> {
        let name = &self.name;
        match read {
            Ok(false) => return Ok(None),
            Ok(true) => {}
            Err(e) => {
                let row = e
                    .position()
                    .map(|p| format!("row {}: ", self.offset + p.line()))
                    .unwrap_or_default();
                return Err(format!("{name}: {row}cannot read the file: {e}"));
            }
        }
        if fields != self.header.len() {
            return Err(format!(
                "{name}: row {line}: {fields} fields, but the header has {} (a ragged row{})",
                self.header.len(),
                if fields < self.header.len() {
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
