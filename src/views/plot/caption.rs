//! A figure with a title above and a caption below, for figures that stand alone (the demo's):
//! the title says what is compared, the caption how to read it.

use super::{DESC_SIZE, DrawResult, FONT, Figure, TITLE_SIZE};
use plotters::coord::Shift;
use plotters::prelude::*;

/// The text around a figure.
#[derive(Debug, Clone, Default)]
pub struct Caption {
    pub title: String,
    /// Wrapped to the figure's width; one paragraph.
    pub text: String,
}

/// Height of a title line [px].
const TITLE_LINE: u32 = 30;
/// Average advance of a title character [px] (bold, [`TITLE_SIZE`] + 3), an over-estimate.
const TITLE_CHAR_WIDTH: f64 = 14.0;
/// Height of one caption line [px].
const LINE: u32 = 22;
/// Average advance of a caption character [px] at [`DESC_SIZE`] in DejaVu Sans (an
/// over-estimate, so that a wrapped line never runs off the figure).
const CHAR_WIDTH: f64 = 8.8;
const MARGIN: i32 = 14;

pub(super) struct Captioned<'a, F> {
    pub(super) figure: &'a F,
    pub(super) caption: &'a Caption,
}

/// `text` broken at spaces into lines of at most `width` characters (a longer word stands
/// alone on its line).
pub(super) fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

impl<F: Figure> Captioned<'_, F> {
    /// The caption's lines, wrapped to the figure's width.
    fn lines(&self) -> Vec<String> {
        wrap(&self.caption.text, self.characters(CHAR_WIDTH))
    }

    /// The title's lines: a figure of one column is narrower than its title.
    fn title_lines(&self) -> Vec<String> {
        wrap(&self.caption.title, self.characters(TITLE_CHAR_WIDTH))
    }

    /// How many characters of `advance` px fit in a line.
    fn characters(&self, advance: f64) -> usize {
        let width = self.figure.size().0 as f64 - 2.0 * MARGIN as f64;
        (width / advance).max(20.0) as usize
    }

    fn title_strip(&self) -> u32 {
        10 + TITLE_LINE * self.title_lines().len() as u32
    }
}

impl<F: Figure> Figure for Captioned<'_, F> {
    fn size(&self) -> (u32, u32) {
        let (w, h) = self.figure.size();
        (
            w,
            self.title_strip() + h + LINE * self.lines().len() as u32 + 12,
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB> {
        let (_, h) = self.figure.size();
        let (title, rest) = root.split_vertically(self.title_strip());
        let (body, caption) = rest.split_vertically(h);
        let bold = FontDesc::new(FontFamily::Name(FONT), TITLE_SIZE + 3.0, FontStyle::Bold);
        let bold = TextStyle::from(bold);
        for (i, line) in self.title_lines().iter().enumerate() {
            title.draw_text(line, &bold, (MARGIN, 8 + (TITLE_LINE * i as u32) as i32))?;
        }
        self.figure.draw(&body)?;
        let style = TextStyle::from(FontDesc::new(
            FontFamily::Name(FONT),
            DESC_SIZE + 1.0,
            FontStyle::Normal,
        ));
        for (i, line) in self.lines().iter().enumerate() {
            caption.draw_text(line, &style, (MARGIN, 4 + (LINE * i as u32) as i32))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::wrap;

    #[test]
    fn wrapping_keeps_every_word_in_order_within_the_width() {
        let text = "the predictor ends closer to the target than stiffness up to 60 ms";
        let lines = wrap(text, 20);
        assert!(lines.iter().all(|l| l.chars().count() <= 20), "{lines:?}");
        assert_eq!(lines.join(" "), text);
        assert_eq!(
            wrap("averyveryverylongword x", 5),
            ["averyveryverylongword", "x"]
        );
        assert!(wrap("  ", 5).is_empty());
    }
}
