//! Command-line parsing shared by the device binary (`omnitrack`) and the desk tool
//! (`omnitrack-desk`): clap's usage errors become one line, like every other error.
//!
//! In: the process arguments and a clap `Parser`. Out: the parsed command, or help/version on
//! stdout (exit 0), or one line on stderr and exit code 2. clap's own report spans the problem,
//! a tip, the usage and a pointer to `--help`; scripts and people reading logs want one line.

use clap::error::ErrorKind;
use clap::Parser;

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
    // The report's lines before the usage: the problem, the missing arguments, a tip.
    let mut problem = String::new();
    for line in text.lines().map(str::trim).take_while(|l| !l.starts_with("Usage:")) {
        if !line.is_empty() {
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
        Build,
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
        let none = line(&["prog"]);
        assert_eq!(none, "prog: no command given (try: prog pose --rig R --lines L)");
        let group = line(&["prog", "table"]);
        assert_eq!(
            group,
            "prog: `prog table` needs one of: build, query (see prog table --help)"
        );
    }
}
