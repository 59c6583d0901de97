//! Command-line parsing shared by the device binary (`omnitrack`) and the desk tool
//! (`omnitrack-desk`): clap's usage errors become one line, like every other error.
//!
//! In: the process arguments and a clap `Parser`. Out: the parsed command, or help/version on
//! stdout (exit 0), or one line on stderr and exit code 2. clap's own report spans the problem,
//! a tip, the usage and a pointer to `--help`; scripts and people reading logs want one line.
//!
//! Also the check that a command line is the one its contract documents ([`undocumented`]): the
//! binaries' tests hold their clap command tree against the command tables of
//! docs/interfaces.md, both ways.

use clap::error::ErrorKind;
use clap::Parser;
use std::collections::{BTreeMap, BTreeSet};

/// Parses the arguments of `program`, or exits: 0 after `--help`/`--version`, 2 after one line
/// naming what is wrong. `no_command` is the line's hint when no subcommand was given.
pub fn parse_or_exit<C: Parser>(program: &str, no_command: &str) -> C {
    match C::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                e.exit()
            }
            eprintln!("{}", usage_error_line(program, no_command, &e));
            std::process::exit(2)
        }
    }
}

/// The one line reporting a clap usage error of `program` (no trailing newline).
pub fn usage_error_line(program: &str, no_command: &str, e: &clap::Error) -> String {
    let text = e.render().to_string();
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand | ErrorKind::MissingSubcommand
    ) {
        // The report is the help of the command that lacks a subcommand: its usage line names
        // the command path, its "Commands:" section the choices.
        let path = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("Usage: "))
            .map(|u| u.split(" <").next().unwrap_or(u).trim().to_string())
            .unwrap_or_default();
        if path.split_whitespace().count() <= 1 {
            return format!("{program}: no command given (try: {no_command})");
        }
        let choices: Vec<&str> = text
            .lines()
            .skip_while(|l| l.trim() != "Commands:")
            .skip(1)
            .take_while(|l| !l.trim().is_empty())
            .filter_map(|l| l.split_whitespace().next())
            .filter(|&c| c != "help")
            .collect();
        return format!(
            "{program}: `{path}` needs one of: {} (see {path} --help)",
            choices.join(", ")
        );
    }
    // The report's lines before the usage: the problem, the missing arguments, a tip. clap's
    // pointer to `--help` is left out: the line ends with its own.
    let mut problem = String::new();
    for line in text.lines().map(str::trim).take_while(|l| !l.starts_with("Usage:")) {
        if !line.is_empty() && !line.starts_with("For more information") {
            if !problem.is_empty() {
                problem.push_str(if problem.ends_with(':') { " " } else { "; " });
            }
            problem.push_str(line);
        }
    }
    format!(
        "{program}: {} (see {program} --help)",
        problem.trim_start_matches("error: ")
    )
}

/// What the contract and the command line disagree on, one line each (empty when they agree).
///
/// `command` is the clap tree of the binary `program`; `doc` the Markdown of its contract
/// (docs/interfaces.md). The contract's commands are the code spans starting with `program`
/// in the first cell of a table row, e.g. `` `omnitrack visibility query --visibility V --at x,y,z` ``:
/// the lower-case words after the program name are the command's path (`visibility query`), and
/// every `--long` in the span is one of its options. Each command of the tree without
/// subcommands (`help` aside) must have such a row naming every long option it takes
/// (`--help` and `--version` aside), and every documented command and option must exist.
pub fn undocumented(command: &clap::Command, program: &str, doc: &str) -> Vec<String> {
    let mut problems = Vec::new();
    let mut actual = BTreeMap::new();
    leaf_commands(command, &mut Vec::new(), &mut actual);
    let mut documented: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for synopsis in synopses(doc, program) {
        let mut words = synopsis.split_whitespace().skip(1).peekable();
        let mut path = Vec::new();
        while let Some(w) = words.next_if(|w| is_command_word(w)) {
            path.push(w);
        }
        documented
            .entry(path.join(" "))
            .or_default()
            .extend(long_options(&synopsis));
    }
    for (path, options) in &actual {
        let Some(written) = documented.get(path) else {
            problems.push(format!("`{program} {path}` is not in the contract's command tables"));
            continue;
        };
        for option in options.difference(written) {
            problems.push(format!(
                "`{program} {path}` takes {option}, which the contract does not name"
            ));
        }
    }
    for (path, written) in &documented {
        let Some(options) = actual.get(path) else {
            problems.push(format!(
                "the contract names `{program} {path}`, which the command line does not have"
            ));
            continue;
        };
        for option in written.difference(options) {
            problems.push(format!(
                "the contract gives `{program} {path}` {option}, which it does not take"
            ));
        }
    }
    problems
}

/// The commands of the tree without subcommands, by path (`visibility build`), with their long
/// options (`--model`), `help` and `--help`/`--version` left out.
fn leaf_commands(command: &clap::Command, path: &mut Vec<String>, out: &mut BTreeMap<String, BTreeSet<String>>) {
    let mut any = false;
    for sub in command.get_subcommands().filter(|s| s.get_name() != "help") {
        any = true;
        path.push(sub.get_name().to_string());
        leaf_commands(sub, path, out);
        path.pop();
    }
    if !any && !path.is_empty() {
        let options = command
            .get_arguments()
            .filter(|a| !a.is_hide_set())
            .filter_map(|a| a.get_long())
            .filter(|l| !matches!(*l, "help" | "version"))
            .map(|l| format!("--{l}"))
            .collect();
        out.insert(path.join(" "), options);
    }
}

/// The code spans starting with `program` (as a word) in the first cell of the doc's table rows.
fn synopses(doc: &str, program: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in doc.lines().map(str::trim) {
        let Some(row) = line.strip_prefix('|') else { continue };
        // The first cell ends at the first `|` that is not escaped (`\|` stands for a `|`).
        let mut cell = String::new();
        let mut chars = row.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '\\' if chars.peek() == Some(&'|') => cell.push(chars.next().unwrap_or('|')),
                '|' => break,
                c => cell.push(c),
            }
        }
        for (i, span) in cell.split('`').enumerate() {
            if i % 2 == 1 && span.split_whitespace().next() == Some(program) {
                out.push(span.to_string());
            }
        }
    }
    out
}

/// A word of a command's path: lower-case letters, digits and inner `-` (`from-kalibr`), not an
/// option, a placeholder (`SHELL`, `IMAGE.png`) or a value (`r_and_t`).
fn is_command_word(word: &str) -> bool {
    word.starts_with(|c: char| c.is_ascii_lowercase())
        && word
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
}

/// Every `--long` option named in a synopsis.
fn long_options(synopsis: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut rest = synopsis;
    while let Some(at) = rest.find("--") {
        let name: String = rest[at + 2..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
            .collect();
        rest = &rest[at + 2 + name.len()..];
        if name.starts_with(|c: char| c.is_ascii_alphanumeric()) {
            out.insert(format!("--{name}"));
        }
    }
    out
}

/// The commands the README gives for `program` (`omnitrack` or `omnitrack-desk`) that clap
/// does not take as written, one line each: every `cargo run … --` line of its code blocks
/// (continued over a trailing `\\`) must parse whole; every `program …` span in backticks in its
/// prose must name commands and options that exist (its arguments may be left out there, as
/// in "`omnitrack-desk extrude`"). A README command that stopped working fails the binary's
/// test, not a newcomer.
pub fn readme_mismatches(command: &clap::Command, program: &str, readme: &str) -> Vec<String> {
    let mut problems = Vec::new();
    let mut check = |line: &str, args: &[&str], whole: bool| {
        let argv = std::iter::once(program).chain(args.iter().copied());
        if let Err(e) = command.clone().try_get_matches_from(argv) {
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                return;
            }
            let partial = matches!(
                e.kind(),
                ErrorKind::MissingRequiredArgument | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            );
            if whole || !partial {
                problems.push(format!("`{line}`: {}", usage_error_line(program, "", &e)));
            }
        }
    };
    // Code blocks: `cargo run [--release] [-p PKG --bin BIN] -- ARGS`.
    let mut in_block = false;
    let mut pending = String::new();
    for raw in readme.lines() {
        if raw.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if !in_block {
            continue;
        }
        let text = raw.split(" #").next().unwrap_or(raw).trim();
        if let Some(head) = text.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(text);
        let line = std::mem::take(&mut pending);
        let Some((cargo, args)) = line.split_once(" -- ") else {
            continue;
        };
        // The examples (`--example`) are programs of their own, not the binaries' commands.
        if !cargo.trim_start().starts_with("cargo run") || cargo.contains("--example") {
            continue;
        }
        // The binary the line runs: `--bin B`, else the package's own (`-p P`: the network
        // crates' binaries are named as their packages), else the front door's. Only
        // `program`'s lines are checked here; the other binaries have their own tests.
        let words: Vec<&str> = cargo.split_whitespace().collect();
        let after = |flags: &[&str]| words.windows(2).find(|w| flags.contains(&w[0])).map(|w| w[1]);
        let runs = after(&["--bin"]).or(after(&["-p", "--package"])).unwrap_or("omnitrack");
        if runs != program {
            continue;
        }
        let args: Vec<&str> = args.split_whitespace().collect();
        check(&line, &args, true);
    }
    // Prose: `program ARGS` in backticks, possibly wrapped over lines.
    let prose: String = readme.split_whitespace().collect::<Vec<_>>().join(" ");
    for (k, span) in prose.split('`').enumerate() {
        if k % 2 == 0 {
            continue;
        }
        let mut words = span.split_whitespace();
        if words.next() != Some(program) {
            continue;
        }
        let args: Vec<&str> = words.collect();
        if args.is_empty()
            || args
                .iter()
                .any(|a| a.contains('|') || a.contains('…') || a.starts_with('['))
        {
            continue;
        }
        check(span, &args, false);
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Parser, Subcommand};

    #[derive(Parser, Debug)]
    struct Cli {
        #[command(subcommand)]
        command: Command,
    }

    #[derive(Subcommand, Debug)]
    enum Command {
        /// Solves.
        Pose {
            #[arg(long)]
            rig: String,
            #[arg(long)]
            lines: String,
        },
        /// A group.
        Table {
            #[command(subcommand)]
            command: Table,
        },
    }

    #[derive(Subcommand, Debug)]
    enum Table {
        /// Builds.
        Build {
            #[arg(long)]
            spacing_m: Option<f64>,
        },
        /// Queries.
        Query,
    }

    fn line(args: &[&str]) -> String {
        let e = Cli::try_parse_from(args).expect_err("a usage error");
        usage_error_line("prog", "prog pose --rig R --lines L", &e)
    }

    #[test]
    fn usage_errors_are_one_line_naming_the_problem() {
        let missing = line(&["prog", "pose"]);
        assert!(!missing.contains('\n'), "{missing}");
        assert!(missing.contains("--rig") && missing.contains("--lines"), "{missing}");
        assert!(missing.ends_with("(see prog --help)"), "{missing}");
        let unknown = line(&["prog", "pose", "--rig", "r", "--lines", "l", "--bogus"]);
        assert!(!unknown.contains('\n') && unknown.contains("'--bogus'"), "{unknown}");
        let value = line(&["prog", "table", "build", "--spacing-m", "wide"]);
        assert!(
            value.starts_with("prog: invalid value 'wide' for '--spacing-m <SPACING_M>': ")
                && value.ends_with("(see prog --help)")
                && !value.contains("For more information"),
            "{value}"
        );
        let none = line(&["prog"]);
        assert_eq!(none, "prog: no command given (try: prog pose --rig R --lines L)");
        let group = line(&["prog", "table"]);
        assert_eq!(
            group,
            "prog: `prog table` needs one of: build, query (see prog table --help)"
        );
    }

    #[test]
    fn the_contract_and_the_command_line_are_compared_both_ways() {
        use clap::CommandFactory;
        let command = Cli::command();
        let agree = "| command | what |\n| --- | --- |\n\
            | `prog pose --rig R --lines L [--method a\\|b]` | solves |\n\
            | `prog table build [--spacing-m S]` / `prog table query` | the table |\n\
            | `progx other --flag` | another program |\n";
        let doc = agree.replace("[--method a\\|b]", "");
        assert_eq!(undocumented(&command, "prog", &doc), Vec::<String>::new());
        // An option documented that the command does not take (behind an escaped `|` too).
        let problems = undocumented(&command, "prog", agree);
        assert_eq!(
            problems,
            ["the contract gives `prog pose` --method, which it does not take"]
        );
        // A command and an option left out of the contract; a command that does not exist.
        let doc = "| `prog pose --rig R` | solves |\n| `prog table query` / `prog table drop` | |\n";
        let problems = undocumented(&command, "prog", doc);
        assert_eq!(
            problems,
            [
                "`prog pose` takes --lines, which the contract does not name",
                "`prog table build` is not in the contract's command tables",
                "the contract names `prog table drop`, which the command line does not have",
            ]
        );
    }

    /// Only `program`'s lines of a README are checked: another package's binary (`-p P`) or
    /// another binary (`--bin B`) takes other commands.
    #[test]
    fn readme_lines_of_other_binaries_are_not_checked() {
        let readme = "```\n\
            cargo run --release -- table query --bogus\n\
            cargo run --release -p omnitrack-ros2 -- publish --capture-clock receipt\n\
            cargo run -p omnitrack-tools --bin omnitrack-desk -- model from-ifc x.ifc\n\
            ```\n";
        let command = <Cli as clap::CommandFactory>::command();
        let problems = readme_mismatches(&command, "omnitrack", readme);
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(problems[0].contains("--bogus"), "{problems:?}");
        assert!(readme_mismatches(&command, "omnitrack-desk", readme)
            .iter()
            .all(|p| p.contains("model")));
    }
}
