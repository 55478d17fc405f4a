//! What `check` prints of its verdict table: on a run of hundreds of verdicts
//! a full table buried the few failing rows (and a passing run printed 520
//! rows to say "nothing to do"). By default only the failing rows are printed,
//! with the summary; `--verbose` prints the whole table. results.json and the
//! report always hold every verdict.
//!
//! The table itself has one formatter, the harness's
//! (`results.format_table`): a header line, one line per verdict with the
//! failing ones first (fail, error, unexpected_pass: `FAILING_STATUSES`), and
//! a count line. The failing rows are therefore its first rows.

/// The table as `check` prints it: all of it when `verbose`, else the header,
/// the `failing` first rows and a line saying how many were left out. A table
/// whose shape is not the formatter's (one line per verdict between a header
/// and a count line) is printed whole, never cut where the rows are unknown.
pub fn shown(table: &str, verdicts: usize, failing: usize, verbose: bool) -> String {
    let lines: Vec<&str> = table.lines().collect();
    if verbose || lines.len() != verdicts + 2 || failing > verdicts {
        return table.to_string();
    }
    let (header, rows, count) = (lines[0], &lines[1..=verdicts], lines[verdicts + 1]);
    let hidden = verdicts - failing;
    let mut out = String::new();
    if failing > 0 {
        out.push_str(header);
        out.push('\n');
        for row in &rows[..failing] {
            out.push_str(row);
            out.push('\n');
        }
    }
    if hidden > 0 {
        out.push_str(&format!(
            "({hidden} passing, skipped or known-failing verdicts not listed: --verbose prints them; results.json and the report have every one)\n"
        ));
    }
    out.push_str(count);
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE: &str = "scene backend buf status\n\
                         a trace id fail\n\
                         b trace Z error\n\
                         a trace Z pass\n\
                         c trace id skipped\n\
                         4 entries: error 1, fail 1, pass 1, skipped 1\n";

    #[test]
    fn only_the_failing_rows_unless_verbose() {
        let quiet = shown(TABLE, 4, 2, false);
        assert!(quiet.contains("a trace id fail") && quiet.contains("b trace Z error"));
        assert!(!quiet.contains("a trace Z pass") && !quiet.contains("c trace id skipped"));
        assert!(quiet.contains("2 passing, skipped or known-failing verdicts not listed"));
        assert!(quiet
            .trim_end()
            .ends_with("4 entries: error 1, fail 1, pass 1, skipped 1"));
        assert_eq!(shown(TABLE, 4, 2, true), TABLE);
    }

    #[test]
    fn a_clean_run_prints_its_summary_only() {
        let quiet = shown(TABLE, 4, 0, false);
        assert!(!quiet.contains("scene backend"), "{quiet}");
        assert_eq!(quiet.lines().count(), 2, "{quiet}");
    }

    #[test]
    fn a_table_of_another_shape_is_printed_whole() {
        assert_eq!(shown(TABLE, 5, 2, false), TABLE);
        assert_eq!(shown("", 0, 0, false), "");
    }
}
