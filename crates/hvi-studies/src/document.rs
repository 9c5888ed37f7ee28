//! A report composed once and rendered twice: as the console's indented text and as a
//! Markdown file. A workflow says what its report holds (facts, tables, notes under headings);
//! the two renderings differ only in form, so the console and the file never disagree.

/// A report: its title, its one-line verdict and its sections, in order.
#[derive(Debug, Clone, Default)]
pub struct Document {
    /// The title (Markdown: the `#` heading; text: the first line, before the verdict).
    pub title: String,
    /// Where the file comes from and its conditions (Markdown only: the console knows).
    pub preamble: String,
    /// The verdict in one line (Markdown: in bold; text: after the title).
    pub verdict: String,
    /// The sections.
    pub sections: Vec<Section>,
}

/// A section of a report: its heading and its blocks.
#[derive(Debug, Clone)]
pub struct Section {
    /// The heading (Markdown: `##`; text: not shown, the labels carry the meaning).
    pub heading: String,
    /// The blocks, in order.
    pub blocks: Vec<Block>,
}

/// One block of a section.
#[derive(Debug, Clone)]
pub enum Block {
    /// A labelled fact. Text: `  label:` padded, then the words, its further lines indented
    /// under them; Markdown: a bullet `- label: words`, its further lines as bullets under it.
    Fact(String, String),
    /// A table. Text: one line per row, the first cell as its label and the others as
    /// `column value`; Markdown: a table.
    Table {
        /// The columns' names.
        header: Vec<String>,
        /// The rows, each as many cells as the header.
        rows: Vec<Vec<String>>,
    },
    /// An explanation for the reader of the file (Markdown only: a paragraph).
    Note(String),
}

impl Section {
    /// An empty section under `heading`.
    pub fn new(heading: impl Into<String>) -> Section {
        Section {
            heading: heading.into(),
            blocks: Vec::new(),
        }
    }

    /// Adds a labelled fact.
    pub fn fact(&mut self, label: impl Into<String>, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Fact(label.into(), text.into()));
        self
    }

    /// Adds a table.
    pub fn table(&mut self, header: &[&str], rows: Vec<Vec<String>>) -> &mut Self {
        self.blocks.push(Block::Table {
            header: header.iter().map(|h| h.to_string()).collect(),
            rows,
        });
        self
    }

    /// Adds a note for the file's reader.
    pub fn note(&mut self, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Note(text.into()));
        self
    }
}

/// The width a text fact's label is padded to (with its colon).
const LABEL_WIDTH: usize = 13;

impl Document {
    /// Adds a section and returns it to fill. Sections left empty are not rendered.
    pub fn section(&mut self, heading: impl Into<String>) -> &mut Section {
        self.sections.push(Section::new(heading));
        self.sections.last_mut().expect("just pushed")
    }

    /// The console's rendering: the title and verdict on one line, then every fact and table
    /// row as an indented line (notes are the file's).
    pub fn text(&self) -> String {
        let mut s = format!("{}: {}\n", self.title, self.verdict);
        for block in self.sections.iter().flat_map(|sec| &sec.blocks) {
            match block {
                Block::Fact(label, text) => {
                    let mut lines = text.lines();
                    s.push_str(&labelled(label, lines.next().unwrap_or("")));
                    for line in lines {
                        s.push_str(&format!("  {:LABEL_WIDTH$}  {}\n", "", line.trim_start()));
                    }
                }
                Block::Table { header, rows } => {
                    for row in rows {
                        let cells = header
                            .iter()
                            .zip(row)
                            .skip(1)
                            .map(|(h, c)| format!("{h} {c}"))
                            .collect::<Vec<_>>()
                            .join(", ");
                        let label = row.first().map_or("", String::as_str);
                        s.push_str(&labelled(label, &cells));
                    }
                }
                Block::Note(_) => {}
            }
        }
        s
    }

    /// The file's rendering: the title as a heading, the preamble, the verdict in bold, then
    /// each section that holds anything under its heading.
    pub fn markdown(&self) -> String {
        let mut s = format!("# {}\n\n", self.title);
        if !self.preamble.is_empty() {
            s.push_str(&format!("{}\n\n", self.preamble));
        }
        s.push_str(&format!("**{}**\n", self.verdict));
        for sec in self.sections.iter().filter(|sec| !sec.blocks.is_empty()) {
            s.push_str(&format!("\n## {}\n", sec.heading));
            let mut previous_fact = false;
            for block in &sec.blocks {
                let is_fact = matches!(block, Block::Fact(..));
                if !(is_fact && previous_fact) {
                    s.push('\n');
                }
                previous_fact = is_fact;
                match block {
                    Block::Fact(label, text) => {
                        let mut lines = text.lines();
                        s.push_str(&format!("- {label}: {}\n", lines.next().unwrap_or("")));
                        for line in lines {
                            s.push_str(&format!("  - {}\n", line.trim()));
                        }
                    }
                    Block::Table { header, rows } => {
                        s.push_str(&format!("| {} |\n", header.join(" | ")));
                        s.push_str(&format!("|{}\n", "---|".repeat(header.len())));
                        for row in rows {
                            s.push_str(&format!("| {} |\n", row.join(" | ")));
                        }
                    }
                    Block::Note(text) => s.push_str(&format!("{text}\n")),
                }
            }
        }
        s
    }
}

/// One text line: the label with its colon, padded (at least one space after it), then `text`.
fn labelled(label: &str, text: &str) -> String {
    let label = format!("{label}:");
    let width = LABEL_WIDTH.max(label.chars().count() + 1);
    format!("  {label:<width$}{text}\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> Document {
        let mut d = Document {
            title: "calibration of `c`".into(),
            preamble: "Written by a test.".into(),
            verdict: "CONVERGED (ego): done".into(),
            sections: Vec::new(),
        };
        d.section("The point")
            .table(
                &["parameter", "best", "paper"],
                vec![vec!["`eps`".into(), "1e-2".into(), "1e-2".into()]],
            )
            .note("An explanation.")
            .fact("best", "eps = 1e-2  J = 0.1\n    R observed 1.5");
        d.section("Nothing here");
        d.section("Cost")
            .fact("runs", "3")
            .fact("wall time", "1 s")
            .fact("a label too long to pad", "x");
        d
    }

    #[test]
    fn the_text_lists_facts_and_rows_and_leaves_the_notes_to_the_file() {
        assert_eq!(
            example().text(),
            "calibration of `c`: CONVERGED (ego): done\n\
             \x20 `eps`:       best 1e-2, paper 1e-2\n\
             \x20 best:        eps = 1e-2  J = 0.1\n\
             \x20                R observed 1.5\n\
             \x20 runs:        3\n\
             \x20 wall time:   1 s\n\
             \x20 a label too long to pad: x\n"
        );
    }

    #[test]
    fn the_markdown_has_headings_tables_notes_and_bullets_and_skips_empty_sections() {
        assert_eq!(
            example().markdown(),
            "# calibration of `c`\n\nWritten by a test.\n\n**CONVERGED (ego): done**\n\n\
             ## The point\n\n| parameter | best | paper |\n|---|---|---|\n| `eps` | 1e-2 | 1e-2 |\n\n\
             An explanation.\n\n- best: eps = 1e-2  J = 0.1\n  - R observed 1.5\n\n\
             ## Cost\n\n- runs: 3\n- wall time: 1 s\n- a label too long to pad: x\n"
        );
    }
}
