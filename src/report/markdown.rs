//! `report.md`: the report as Markdown, with the images and plots linked by relative path (the
//! folder is self-contained; `report.html` embeds the same images).

use super::Page;

/// Escape the characters that would break a Markdown table cell.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

/// One Markdown table row.
fn row<S: AsRef<str>>(cells: &[S]) -> String {
    let cells: Vec<String> = cells.iter().map(|c| cell(c.as_ref())).collect();
    format!("| {} |\n", cells.join(" | "))
}

pub fn render(report: &dyn Page) -> String {
    let mut md = format!("# {}\n\n", report.title());
    for (label, value) in report.settings() {
        md += &format!("- {label}: {value}\n");
    }
    md += "\n## Verdict\n\n";
    for verdict in report.verdict_lines() {
        md += &format!("- {verdict}\n");
    }
    for table in report.tables() {
        md += &format!("\n## {}\n\n", table.heading);
        md += &row(&table.header);
        md += &row(&vec!["---"; table.header.len()]);
        for cells in &table.rows {
            md += &row(cells);
        }
        if let Some(note) = &table.note {
            md += &format!("\n{note}\n");
        }
    }
    md += "\n## Plots\n\n";
    for (caption, path) in report.figures() {
        md += &format!("![{caption}]({path})\n\n");
    }
    let relit = report.relit();
    md += &format!("## Under new light\n\n{}\n\n", relit.description());
    md += &grid(&relit.grid());
    md += &format!(
        "![difference colour bar]({})\n\n",
        relit.difference_colour_bar
    );
    md += "## Photos\n\n";
    md += &grid(&report.image_grid());
    md
}

/// Rows of captioned images, each a heading and a one-row table of its cells.
fn grid(rows: &[(String, Vec<(String, String)>)]) -> String {
    let mut md = String::new();
    for (heading, cells) in rows {
        md += &format!("### {heading}\n\n");
        let captions: Vec<&str> = cells.iter().map(|c| c.0.as_str()).collect();
        md += &row(&captions);
        md += &row(&vec!["---"; cells.len()]);
        let images: Vec<String> = cells
            .iter()
            .map(|(caption, path)| format!("![{caption}]({path})"))
            .collect();
        md += &row(&images);
        md += "\n";
    }
    md
}
