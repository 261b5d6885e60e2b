//! The CSV reading both `kalibra eval` and `kalibra tune` share: a header, then rows of the
//! header's length, with errors that name the file, the row (the header is row 1) and the
//! column.

use std::io::Read;
use std::path::Path;

use crate::error::Error;

/// A CSV file's header and a reader positioned after it, over any byte source (a file read
/// as it goes, or bytes in memory).
pub(crate) struct Rows<'f, R: Read> {
    /// The file, as errors name it.
    file: &'f Path,
    reader: csv::Reader<R>,
    /// The header's cells, trimmed.
    pub header: csv::StringRecord,
    /// The row number of the source's first line, less 1 (0 when the source holds the header).
    offset: u64,
}

impl<'f, R: Read> Rows<'f, R> {
    /// Reads the header of `source` (the file `file`).
    pub fn new(file: &'f Path, source: R) -> Result<Self, Error> {
        let mut reader = csv::ReaderBuilder::new()
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(source);
        let header = reader
            .headers()
            .map_err(|e| Error::csv(file, Some(1), format!("cannot read the header: {e}")))?
            .clone();
        Ok(Self {
            file,
            reader,
            header,
            offset: 0,
        })
    }

    /// Rows of `source`, a later piece of the file `file` whose header is `header`; the
    /// piece's first line is row `first_row` of the file, and starts a record. Fields are
    /// not trimmed: the caller trims the fields it reads (trimming every field of a byte
    /// record copies the record).
    pub fn continuing(
        file: &'f Path,
        source: R,
        header: csv::StringRecord,
        first_row: u64,
    ) -> Self {
        let reader = csv::ReaderBuilder::new()
            .flexible(true)
            .has_headers(false)
            .from_reader(source);
        Self {
            file,
            reader,
            header,
            offset: first_row - 1,
        }
    }

    /// Reads the next row into `record` and returns its row number, `None` at the end. A row
    /// whose length differs from the header's is an error (a ragged or truncated file).
    pub fn next_row(&mut self, record: &mut csv::StringRecord) -> Result<Option<u64>, Error> {
        let read = self.reader.read_record(record);
        let line = self.offset + record.position().map_or(0, |p| p.line());
        self.checked(read, line, record.len())
    }

    /// As [`Rows::next_row`], into a byte record: no UTF-8 check of every cell, for the large
    /// logs where that check costs (numbers are ASCII; a cell that is not is reported when
    /// parsed).
    pub fn next_byte_row(&mut self, record: &mut csv::ByteRecord) -> Result<Option<u64>, Error> {
        let read = self.reader.read_byte_record(record);
        let line = self.offset + record.position().map_or(0, |p| p.line());
        self.checked(read, line, record.len())
    }

    fn checked(
        &self,
        read: csv::Result<bool>,
        line: u64,
        fields: usize,
    ) -> Result<Option<u64>, Error> {
        match read {
            Ok(false) => return Ok(None),
            Ok(true) => {}
            Err(e) => {
                let row = e.position().map(|p| self.offset + p.line());
                return Err(Error::csv(
                    self.file,
                    row,
                    format!("cannot read the file: {e}"),
                ));
            }
        }
        if fields != self.header.len() {
            return Err(Error::csv(
                self.file,
                Some(line),
                format!(
                    "{fields} fields, but the header has {} (a ragged row{})",
                    self.header.len(),
                    if fields < self.header.len() {
                        "; is the file truncated?"
                    } else {
                        ""
                    }
                ),
            ));
        }
        Ok(Some(line))
    }

    /// An error about the cell in row `line` and column `c` (from 0).
    pub fn cell_error(&self, line: u64, c: usize, message: String) -> Error {
        Error::Csv {
            file: self.file.to_path_buf(),
            row: Some(line),
            column: Some(c + 1),
            column_name: Some(self.header[c].to_string()),
            message,
        }
    }

    /// An error about the header's column `c` (from 0), in row 1.
    pub fn header_error(&self, c: usize, message: String) -> Error {
        Error::Csv {
            file: self.file.to_path_buf(),
            row: Some(1),
            column: Some(c + 1),
            column_name: None,
            message,
        }
    }
}
