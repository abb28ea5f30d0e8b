//! The report as a document: headings, paragraphs, tables and figures,
//! rendered once as Markdown (`report.md`, figures linked) and once as a
//! self-contained HTML page (`index.html`, figures embedded), so that the
//! two always say the same.

use std::fmt::Write;
use std::path::Path;

/// One block of the document.
#[derive(Clone, Debug)]
pub enum Block {
    Heading(u8, String),
    Paragraph(String),
    Table(Table),
    /// Figures side by side, each a file in the report's folder with a
    /// caption.
    Figures(Vec<Figure>),
    Bullets(Vec<String>),
}

/// A figure: a PNG or SVG in the report's folder.
#[derive(Clone, Debug)]
pub struct Figure {
    /// Path relative to the report's folder.
    pub path: String,
    pub caption: String,
}

/// A table of text cells; `numeric[c]` right-aligns column `c`.
#[derive(Clone, Debug, Default)]
pub struct Table {
    pub header: Vec<String>,
    pub numeric: Vec<bool>,
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// A table with these column names; a name ending in `#` is numeric
    /// (the `#` is dropped).
    pub fn new(columns: &[&str]) -> Table {
        Table {
            header: columns
                .iter()
                .map(|c| c.trim_end_matches('#').to_string())
                .collect(),
            numeric: columns.iter().map(|c| c.ends_with('#')).collect(),
            rows: Vec::new(),
        }
    }

    pub fn row(&mut self, cells: Vec<String>) {
        self.rows.push(cells);
    }

    /// The table as Markdown: numeric columns right-aligned, `|` escaped
    /// and line breaks as spaces in every cell.
    pub fn markdown(&self) -> String {
        let cell = |c: &String| c.replace('|', "\\|").replace(['\n', '\r'], " ");
        let line = |row: &[String]| {
            let cells: Vec<String> = row.iter().map(cell).collect();
            format!("| {} |\n", cells.join(" | "))
        };
        let align: Vec<&str> = (0..self.header.len())
            .map(|c| match self.numeric.get(c) {
                Some(true) => "---:",
                _ => "---",
            })
            .collect();
        let mut out = line(&self.header);
        let _ = writeln!(out, "|{}|", align.join("|"));
        for row in &self.rows {
            out.push_str(&line(row));
        }
        out
    }

    /// The table as CSV (RFC 4180 quoting).
    pub fn csv(&self) -> String {
        let quote = |s: &String| {
            if s.contains([',', '"', '\n', '\r']) {
                format!("\"{}\"", s.replace('"', "\"\""))
            } else {
                s.clone()
            }
        };
        let mut out = String::new();
        for row in std::iter::once(&self.header).chain(&self.rows) {
            let cells: Vec<String> = row.iter().map(quote).collect();
            let _ = writeln!(out, "{}", cells.join(","));
        }
        out
    }
}

/// The whole document.
#[derive(Clone, Debug, Default)]
pub struct Document {
    pub title: String,
    pub blocks: Vec<Block>,
}

impl Document {
    pub fn push(&mut self, block: Block) {
        self.blocks.push(block);
    }

    pub fn markdown(&self) -> String {
        let mut s = format!("# {}\n\n", self.title);
        for block in &self.blocks {
            match block {
                Block::Heading(level, text) => {
                    let _ = writeln!(s, "{} {text}\n", "#".repeat(usize::from(*level)));
                }
                Block::Paragraph(text) => {
                    let _ = writeln!(s, "{text}\n");
                }
                Block::Bullets(items) => {
                    for item in items {
                        let _ = writeln!(s, "- {item}");
                    }
                    s.push('\n');
                }
                Block::Table(t) => {
                    s.push_str(&t.markdown());
                    s.push('\n');
                }
                Block::Figures(figures) if figures.len() == 1 => {
                    let f = &figures[0];
                    let _ = writeln!(s, "![{}]({})\n", f.caption, f.path);
                }
                Block::Figures(figures) => {
                    let captions: Vec<&str> = figures.iter().map(|f| f.caption.as_str()).collect();
                    let _ = writeln!(s, "| {} |", captions.join(" | "));
                    let _ = writeln!(s, "|{}", "---|".repeat(figures.len()));
                    let images: Vec<String> = figures
                        .iter()
                        .map(|f| format!("![{}]({})", f.caption, f.path))
                        .collect();
                    let _ = writeln!(s, "| {} |\n", images.join(" | "));
                }
            }
        }
        s
    }

    /// The page, every figure embedded from `dir` as a data URI (a figure
    /// that cannot be read is shown as its caption, marked missing).
    pub fn html(&self, dir: &Path) -> String {
        let mut s = String::new();
        let _ = write!(
            s,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
             <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
            escape(&self.title),
            escape(&self.title)
        );
        for block in &self.blocks {
            match block {
                Block::Heading(level, text) => {
                    let id: String = text
                        .to_lowercase()
                        .chars()
                        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
                        .collect();
                    let _ = writeln!(s, "<h{level} id=\"{id}\">{}</h{level}>", escape(text));
                }
                Block::Paragraph(text) => {
                    let _ = writeln!(s, "<p>{}</p>", inline(text));
                }
                Block::Bullets(items) => {
                    s.push_str("<ul>\n");
                    for item in items {
                        let _ = writeln!(s, "<li>{}</li>", inline(item));
                    }
                    s.push_str("</ul>\n");
                }
                Block::Table(t) => {
                    s.push_str("<div class=\"scroll\"><table>\n<thead><tr>");
                    for h in &t.header {
                        let _ = write!(s, "<th>{}</th>", escape(h));
                    }
                    s.push_str("</tr></thead>\n<tbody>\n");
                    for row in &t.rows {
                        s.push_str("<tr>");
                        for (c, cell) in row.iter().enumerate() {
                            let class = if t.numeric.get(c) == Some(&true) {
                                " class=\"num\""
                            } else {
                                ""
                            };
                            let _ = write!(s, "<td{class}>{}</td>", inline(cell));
                        }
                        s.push_str("</tr>\n");
                    }
                    s.push_str("</tbody></table></div>\n");
                }
                Block::Figures(figures) => {
                    s.push_str("<div class=\"figures\">\n");
                    for f in figures {
                        let _ = writeln!(
                            s,
                            "<figure>{}<figcaption>{}</figcaption></figure>",
                            embedded(dir, f),
                            escape(&f.caption)
                        );
                    }
                    s.push_str("</div>\n");
                }
            }
        }
        s.push_str("</body>\n</html>\n");
        s
    }
}

const STYLE: &str = "body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;\
padding:0 1em;color:#222;line-height:1.45}table{border-collapse:collapse;font-size:0.9em}\
th,td{border:1px solid #ccc;padding:0.25em 0.5em}th{background:#f2f2f2}td.num{text-align:right;\
font-variant-numeric:tabular-nums}.scroll{overflow-x:auto}.figures{display:flex;flex-wrap:wrap;\
gap:0.75em}figure{margin:0}figure img{max-width:100%;border:1px solid #ddd}\
figcaption{font-size:0.85em;color:#555}code{background:#f4f4f4;padding:0 0.2em}";

/// An `<img>` with the figure's bytes as a data URI.
fn embedded(dir: &Path, figure: &Figure) -> String {
    let mime = if figure.path.ends_with(".svg") {
        "image/svg+xml"
    } else {
        "image/png"
    };
    match std::fs::read(dir.join(&figure.path)) {
        Ok(bytes) => format!(
            "<img src=\"data:{mime};base64,{}\" alt=\"{}\">",
            base64(&bytes),
            escape(&figure.caption)
        ),
        Err(_) => format!("<span>[missing: {}]</span>", escape(&figure.path)),
    }
}

/// HTML-escaped text with Markdown's `code` spans kept.
fn inline(text: &str) -> String {
    let mut out = String::new();
    for (i, part) in escape(text).split('`').enumerate() {
        if i % 2 == 1 {
            let _ = write!(out, "<code>{part}</code>");
        } else {
            out.push_str(part);
        }
    }
    out
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn one_document_renders_as_markdown_html_and_csv() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a.png"), b"\x89PNG").unwrap();
        let mut table = Table::new(&["method", "error#"]);
        table.row(vec!["a|b".into(), "1.5%".into()]);
        table.row(vec!["x, \"y\"".into(), "2%".into()]);
        let mut doc = Document {
            title: "T & <t>".into(),
            blocks: Vec::new(),
        };
        doc.push(Block::Paragraph("see `code`".into()));
        doc.push(Block::Table(table.clone()));
        doc.push(Block::Figures(vec![Figure {
            path: "a.png".into(),
            caption: "chart".into(),
        }]));
        let md = doc.markdown();
        assert!(
            md.contains("| a\\|b | 1.5% |")
                && md.contains("|---|---:|")
                && md.contains("![chart](a.png)")
        );
        let html = doc.html(dir.path());
        assert!(html.contains("<title>T &amp; &lt;t&gt;</title>"));
        assert!(
            html.contains("<code>code</code>") && html.contains("data:image/png;base64,iVBORw==")
        );
        assert!(html.contains("<td class=\"num\">1.5%</td>"));
        assert_eq!(table.csv(), "method,error\na|b,1.5%\n\"x, \"\"y\"\"\",2%\n");
    }
}
