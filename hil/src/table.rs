//! Markdown tables, written one way everywhere: a header, its alignment row and a line per row,
//! each cell's `|` escaped and its line breaks made spaces so that a cell can never break the
//! table.

/// How a column's cells align.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// The renderer's default (left).
    Left,
    /// Right, for figures.
    Right,
}

/// A Markdown table being written.
#[derive(Debug, Clone)]
pub struct Table {
    text: String,
    columns: usize,
}

impl Table {
    /// A table of the columns `(heading, alignment)`.
    pub fn new(columns: &[(&str, Align)]) -> Self {
        let mut text = line(columns.iter().map(|c| c.0));
        text += "|";
        for c in columns {
            text += match c.1 {
                Align::Left => "---|",
                Align::Right => "---:|",
            };
        }
        text += "\n";
        Self {
            text,
            columns: columns.len(),
        }
    }

    /// A table whose columns all align left.
    pub fn left(headings: &[&str]) -> Self {
        let cols: Vec<(&str, Align)> = headings.iter().map(|h| (*h, Align::Left)).collect();
        Self::new(&cols)
    }

    /// A table whose first column aligns left and the others right (a name, then figures).
    pub fn figures(headings: &[&str]) -> Self {
        let cols: Vec<(&str, Align)> = headings
            .iter()
            .enumerate()
            .map(|(i, h)| (*h, if i == 0 { Align::Left } else { Align::Right }))
            .collect();
        Self::new(&cols)
    }

    /// One row, a cell per column (a row of another width is a bug of the caller's, caught by
    /// the tests).
    pub fn row<S: AsRef<str>>(&mut self, cells: impl IntoIterator<Item = S>) -> &mut Self {
        let cells: Vec<String> = cells.into_iter().map(|c| cell(c.as_ref())).collect();
        debug_assert_eq!(cells.len(), self.columns, "a row of {cells:?}");
        self.text += &line(cells.iter().map(String::as_str));
        self
    }

    /// The table's text, ending in a line break.
    pub fn finish(&self) -> String {
        self.text.clone()
    }
}

/// One line of the table: `| a | b |`.
fn line<'a>(cells: impl Iterator<Item = &'a str>) -> String {
    let mut s = String::from("|");
    for c in cells {
        if !c.is_empty() {
            s += " ";
            s += c;
        }
        s += " |";
    }
    s + "\n"
}

/// A cell's text that cannot break the table.
fn cell(t: &str) -> String {
    t.replace('|', "\\|").replace(['\r', '\n'], " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_reads_as_markdown_and_a_cell_cannot_break_it() {
        let mut t = Table::figures(&["case", "error"]);
        t.row(["a | b", "1.5"]).row(["two\nlines", "2"]);
        assert_eq!(
            t.finish(),
            "| case | error |\n|---|---:|\n| a \\| b | 1.5 |\n| two lines | 2 |\n"
        );
        assert_eq!(Table::left(&["", "x"]).finish(), "| | x |\n|---|---|\n");
    }
}
