//! Manual pages and shell completions of omnitrack's binaries (`omnitrack`, `omnitrack-desk`,
//! `omnitrack-link`, `omnitrack-ros2`), generated from their clap command lines.
//!
//! In: a binary's clap [`Command`](clap::Command). Out: roff manual pages, one for the binary and
//! one for each of its commands (`omnitrack.1`, `omnitrack-run.1`, `omnitrack-visibility.1`,
//! `omnitrack-visibility-build.1`, …; the pages that list commands cite exactly these), and
//! completion scripts. Every binary offers them the same way: `BIN completions SHELL` and
//! `BIN manpage [--dir DIR]` ([`ManpageArgs`], [`run_manpage`], [`run_completions`]).
//!
//! A command's `after_help` that is the binary's exit-status text ([`Manual::exit_status`]) is
//! rendered as an EXIT STATUS section (clap_mangen would run it together as "EXTRA"). Everything
//! is rendered into memory first: clap_complete panics on a failed write, and a closed pipe
//! should be one error, not half a page.

pub use clap_complete::Shell;
use std::io::Write;
use std::path::{Path, PathBuf};

/// How a binary's manual is made: its command line, and the help text of its exit codes.
pub struct Manual {
    command: clap::Command,
    exit_status: Option<&'static str>,
}

/// `BIN manpage [--dir DIR]`: the arguments every binary's `manpage` command takes.
#[derive(Debug, Clone, clap::Args)]
pub struct ManpageArgs {
    /// Write the binary's page and one page per command (BIN-COMMAND.1) into this directory
    /// instead of printing the binary's page.
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
}

impl Manual {
    /// The manual of the binary whose command line is `command`.
    pub fn new(command: clap::Command) -> Manual {
        // Every page names the version; `help` is no command of its own in a manual.
        let mut command = command.propagate_version(true).disable_help_subcommand(true);
        command.build();
        Manual {
            command,
            exit_status: None,
        }
    }

    /// `text` (the `after_help` of the commands that have it: a first line, then one
    /// `  CODE  meaning` line per code) becomes an EXIT STATUS section of their pages.
    pub fn exit_status(mut self, text: &'static str) -> Manual {
        self.exit_status = Some(text);
        self
    }

    /// Every page: (file name, roff), the binary's first, then its commands' depth first.
    pub fn pages(&self) -> std::io::Result<Vec<(String, Vec<u8>)>> {
        let mut pages = Vec::new();
        self.collect(&self.command, &mut pages)?;
        Ok(pages)
    }

    /// The binary's own page (the first of [`Manual::pages`]).
    pub fn page(&self) -> std::io::Result<Vec<u8>> {
        let mut out = Vec::new();
        self.render(&self.command, &mut out)?;
        Ok(out)
    }

    /// Writes every page into `dir` (made if absent); returns the files written.
    pub fn write_to(&self, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir)?;
        let mut written = Vec::new();
        for (name, page) in self.pages()? {
            let path = dir.join(name);
            std::fs::write(&path, page)?;
            written.push(path);
        }
        Ok(written)
    }

    /// The completion script of `shell`.
    pub fn completions(&self, shell: Shell) -> Vec<u8> {
        let mut command = self.command.clone();
        let name = command.get_name().to_string();
        let mut script = Vec::new();
        clap_complete::generate(shell, &mut command, name, &mut script);
        script
    }

    fn collect(&self, command: &clap::Command, pages: &mut Vec<(String, Vec<u8>)>) -> std::io::Result<()> {
        let mut page = Vec::new();
        self.render(command, &mut page)?;
        pages.push((clap_mangen::Man::new(command.clone()).get_filename(), page));
        for sub in command.get_subcommands().filter(|s| !s.is_hide_set()) {
            self.collect(sub, pages)?;
        }
        Ok(())
    }

    fn render(&self, command: &clap::Command, out: &mut dyn Write) -> std::io::Result<()> {
        let man = clap_mangen::Man::new(command.clone());
        man.render_title(out)?;
        man.render_name_section(out)?;
        man.render_synopsis_section(out)?;
        man.render_description_section(out)?;
        if command.get_arguments().any(|a| !a.is_hide_set()) {
            man.render_options_section(out)?;
        }
        if command.get_subcommands().any(|s| !s.is_hide_set()) {
            man.render_subcommands_section(out)?;
        }
        let after = command.get_after_help().map(|h| h.to_string());
        match (after, self.exit_status) {
            (Some(text), Some(exit)) if text == exit => {
                writeln!(out, ".SH \"EXIT STATUS\"")?;
                for line in exit.lines().skip(1) {
                    let (code, meaning) = line.trim().split_once("  ").unwrap_or((line.trim(), ""));
                    writeln!(out, ".TP\n{code}\n{}", meaning.trim().replace('-', "\\-"))?;
                }
            }
            (Some(_), _) => man.render_extra_section(out)?,
            (None, _) => {}
        }
        if command.get_version().is_some() {
            man.render_version_section(out)?;
        }
        Ok(())
    }
}

/// The manual pages a page cites, `name(section)` of the roff text (e.g. `omnitrack-run(1)`).
pub fn cited_pages(roff: &str) -> Vec<String> {
    let mut cited = Vec::new();
    // roff writes a hyphen as `\-`.
    let roff = roff.replace("\\-", "-");
    for word in roff.split(|c: char| c.is_whitespace() || c == '"') {
        let Some((name, rest)) = word.split_once('(') else {
            continue;
        };
        let Some((section, _)) = rest.split_once(')') else {
            continue;
        };
        let name = name.trim_start_matches("\\fB").trim_start_matches("\\fR");
        if !name.is_empty()
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
            && section.len() == 1
            && section.chars().all(|c| c.is_ascii_digit())
        {
            cited.push(format!("{name}.{section}"));
        }
    }
    cited
}

/// The citations of the pages in `dir` that lead to no page there, as `PAGE cites NAME.1`
/// (empty when every cited page was made).
pub fn dangling_citations(dir: &Path) -> std::io::Result<Vec<String>> {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        names.push(entry?.file_name().to_string_lossy().into_owned());
    }
    let mut dangling = Vec::new();
    for name in &names {
        let page = std::fs::read_to_string(dir.join(name))?;
        for cited in cited_pages(&page) {
            if !names.contains(&cited) {
                dangling.push(format!("{name} cites {cited}"));
            }
        }
    }
    Ok(dangling)
}

/// `BIN manpage [--dir DIR]`: the binary's page on standard output, or every page into `DIR`
/// (their paths on standard error).
pub fn run_manpage(manual: &Manual, args: &ManpageArgs) -> std::io::Result<()> {
    match &args.dir {
        None => std::io::stdout().lock().write_all(&manual.page()?),
        Some(dir) => {
            let written = manual
                .write_to(dir)
                .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", dir.display())))?;
            for path in written {
                eprintln!("{}", path.display());
            }
            Ok(())
        }
    }
}

/// `BIN completions SHELL`: the completion script on standard output.
pub fn run_completions(manual: &Manual, shell: Shell) -> std::io::Result<()> {
    std::io::stdout().lock().write_all(&manual.completions(shell))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{CommandFactory, Parser, Subcommand};

    #[derive(Parser)]
    #[command(name = "demo-bin", version, about = "A binary", after_help = EXIT)]
    struct Cli {
        #[command(subcommand)]
        command: Command,
    }

    #[derive(Subcommand)]
    enum Command {
        /// Runs.
        #[command(after_help = EXIT)]
        Run {
            #[arg(long)]
            fast: bool,
        },
        /// Tables.
        Table {
            #[command(subcommand)]
            command: TableCommand,
        },
    }

    #[derive(Subcommand)]
    enum TableCommand {
        /// Builds.
        Build,
    }

    const EXIT: &str = "Exit status:\n  0  fine\n  2  bad input";

    #[test]
    fn every_page_a_page_cites_is_made_and_commands_have_their_own() {
        let manual = Manual::new(Cli::command()).exit_status(EXIT);
        let pages = manual.pages().unwrap();
        let names: Vec<&str> = pages.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            [
                "demo-bin.1",
                "demo-bin-run.1",
                "demo-bin-table.1",
                "demo-bin-table-build.1"
            ]
        );
        for (name, page) in &pages {
            let text = String::from_utf8(page.clone()).unwrap();
            for cited in cited_pages(&text) {
                assert!(names.contains(&cited.as_str()), "{name} cites {cited}, not made");
            }
            assert!(!text.contains("help(1)"), "{name}: {text}");
            assert!(text.contains(".SH VERSION"), "{name}: {text}");
        }
        let top = String::from_utf8(pages[0].1.clone()).unwrap();
        assert!(cited_pages(&top).contains(&"demo-bin-run.1".to_string()), "{top}");
        let run = String::from_utf8(pages[1].1.clone()).unwrap();
        assert!(
            run.contains(".SH \"EXIT STATUS\"\n.TP\n0\nfine\n.TP\n2\nbad input\n"),
            "{run}"
        );
        assert!(run.contains("\\-\\-fast"), "{run}");
    }

    #[test]
    fn completions_name_the_commands() {
        let manual = Manual::new(Cli::command());
        let script = String::from_utf8(manual.completions(clap_complete::Shell::Bash)).unwrap();
        assert!(script.contains("demo-bin") && script.contains("table"), "{script}");
    }
}
