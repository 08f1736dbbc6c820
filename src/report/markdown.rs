//! `report.md`: the report as Markdown, with the images and plots linked by relative path (the
//! folder is self-contained; `report.html` embeds the same images).

use super::Report;

/// Escape the characters that would break a Markdown table cell.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

/// One Markdown table row.
fn row<S: AsRef<str>>(cells: &[S]) -> String {
    let cells: Vec<String> = cells.iter().map(|c| cell(c.as_ref())).collect();
    format!("| {} |\n", cells.join(" | "))
}

pub fn render(report: &Report) -> String {
    let mut md = format!("# Model comparison: {}\n\n", report.capture_name);
    for (label, value) in report.settings() {
        md += &format!("- {label}: {value}\n");
    }
    md += "\n## Verdict\n\n";
    for verdict in &report.verdicts {
        md += &format!("- {verdict}\n");
    }
    md += "\n## Models\n\n";
    let header = Report::table_header();
    md += &row(&header);
    md += &row(&header.map(|_| "---"));
    for cells in report.table_rows() {
        md += &row(&cells);
    }
    md += "\nBIC = N ln(RSS/N) + k ln N (Gaussian noise of unknown variance, N = pixels x 3). \
           Delta-BIC on the Kass & Raftery scale: < 2 not distinguishable, 2-6 positive, \
           6-10 strong, > 10 very strong.\n\n## Plots\n\n";
    for (caption, path) in report.plots() {
        md += &format!("![{caption}]({path})\n\n");
    }
    md += "## Photos\n\n";
    for (stem, cells) in report.image_grid() {
        md += &format!("### {stem}\n\n");
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
