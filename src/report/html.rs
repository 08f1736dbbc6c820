//! `report.html`: the report as one self-contained page: inline CSS, every image embedded as a
//! base64 `data:image/png` URI, no script and no network access.

use super::Page;
use crate::error::{Error, Result};
use base64::Engine;
use std::path::Path;

const STYLE: &str = "body{font-family:sans-serif;margin:2em;color:#222}\
table{border-collapse:collapse;margin:1em 0}\
th,td{border:1px solid #bbb;padding:4px 8px;text-align:left;vertical-align:top}\
th{background:#eee}img.photo{width:160px;image-rendering:pixelated}\
img.plot{max-width:100%}img.relit{width:192px}figure{display:inline-block;margin:4px}\
figcaption{font-size:small;text-align:center}";

/// Escape text for HTML element content and attribute values.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A PNG file under `root` as a data URI.
fn data_uri(root: &Path, relative: &str) -> Result<String> {
    let path = root.join(relative);
    let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
    Ok(format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bytes)
    ))
}

/// An `<img>` of a PNG under `root`, embedded, with `class` and `caption` as alt text.
fn image(root: &Path, relative: &str, class: &str, caption: &str) -> Result<String> {
    Ok(format!(
        "<img class=\"{class}\" alt=\"{}\" src=\"{}\">",
        escape(caption),
        data_uri(root, relative)?
    ))
}

/// The page of `report`, whose images have been written under `root`.
pub fn render(report: &dyn Page, root: &Path) -> Result<String> {
    let title = escape(&report.title());
    let mut html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title>\
         <style>{STYLE}</style></head><body>\n<h1>{title}</h1>\n<ul>\n"
    );
    for (label, value) in report.settings() {
        html += &format!("<li>{label}: {}</li>\n", escape(&value));
    }
    html += "</ul>\n<h2>Verdict</h2>\n<ul>\n";
    for verdict in report.verdict_lines() {
        html += &format!("<li>{}</li>\n", escape(verdict));
    }
    html += "</ul>\n";
    for table in report.tables() {
        html += &format!("<h2>{}</h2>\n<table>\n<tr>", escape(&table.heading));
        for heading in &table.header {
            html += &format!("<th>{}</th>", escape(heading));
        }
        html += "</tr>\n";
        for cells in &table.rows {
            html += "<tr>";
            for cell in cells {
                html += &format!("<td>{}</td>", escape(cell));
            }
            html += "</tr>\n";
        }
        html += "</table>\n";
        if let Some(note) = &table.note {
            html += &format!("<p>{}</p>\n", escape(note));
        }
    }
    html += "<h2>Plots</h2>\n";
    for (caption, path) in report.figures() {
        html += &format!(
            "<figure>{}<figcaption>{}</figcaption></figure>\n",
            image(root, &path, "plot", &caption)?,
            escape(&caption)
        );
    }
    let relit = report.relit();
    html += &format!(
        "<h2>Under new light</h2>\n<p>{}</p>\n",
        escape(&relit.description())
    );
    html += &grid(root, &relit.grid(), "relit")?;
    html += &format!(
        "<figure>{}</figure>\n",
        image(
            root,
            &relit.difference_colour_bar,
            "plot",
            "difference colour bar"
        )?
    );
    html += "<h2>Photos</h2>\n";
    html += &grid(root, &report.image_grid(), "photo")?;
    html += "</body></html>\n";
    Ok(html)
}

/// Rows of captioned images under `root` (per row its heading and `(caption, relative path)`
/// cells), the images of class `class`.
fn grid(root: &Path, rows: &[(String, Vec<(String, String)>)], class: &str) -> Result<String> {
    let mut html = String::new();
    for (heading, cells) in rows {
        html += &format!("<h3>{}</h3>\n<div>", escape(heading));
        for (caption, path) in cells {
            html += &format!(
                "<figure>{}<figcaption>{}</figcaption></figure>",
                image(root, path, class, caption)?,
                escape(caption)
            );
        }
        html += "</div>\n";
    }
    Ok(html)
}
