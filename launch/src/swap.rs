//! `--swap ROLE=COMMAND`: run another program in a role, e.g. a Python planner.

use crate::LaunchError;
use crate::launch_file::LaunchFile;

/// Parses `ROLE=COMMAND` and splits COMMAND like a POSIX shell would split words: whitespace
/// separates, `'...'` is literal, `"..."` keeps spaces and honours `\"`, `\\`, `\$` and `` \` ``,
/// and a backslash outside quotes escapes the next character. No expansion of any kind.
pub fn parse_swap(arg: &str) -> Result<(String, Vec<String>), LaunchError> {
    let bad = |reason: &str| LaunchError::BadSwap {
        arg: arg.to_owned(),
        reason: reason.to_owned(),
    };
    let (role, command) = arg
        .split_once('=')
        .ok_or_else(|| bad("expected ROLE=COMMAND, e.g. planning=python3 examples/p.py"))?;
    let role = role.trim();
    if role.is_empty() {
        return Err(bad("the role before `=` is empty"));
    }
    if role.chars().any(char::is_whitespace) {
        return Err(bad("the role before `=` contains whitespace"));
    }
    let argv = split_words(command).map_err(&bad)?;
    if argv.is_empty() {
        return Err(bad("the command after `=` is empty"));
    }
    Ok((role.to_owned(), argv))
}

/// Shell-like word splitting (POSIX "Token Recognition", quoting rules only).
pub(crate) fn split_words(s: &str) -> Result<Vec<String>, &'static str> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        match c {
            '\'' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('\'') => break,
                        Some(q) => word.push(q),
                        None => return Err("unterminated single quote"),
                    }
                }
            }
            '"' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('"') => break,
                        Some('\\') => match chars.next() {
                            Some(e @ ('"' | '\\' | '$' | '`')) => word.push(e),
                            Some('\n') => {}
                            Some(other) => {
                                word.push('\\');
                                word.push(other);
                            }
                            None => return Err("unterminated double quote"),
                        },
                        Some(q) => word.push(q),
                        None => return Err("unterminated double quote"),
                    }
                }
            }
            '\\' => {
                in_word = true;
                match chars.next() {
                    Some('\n') => {}
                    Some(e) => word.push(e),
                    None => return Err("trailing backslash"),
                }
            }
            c if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            c => {
                in_word = true;
                word.push(c);
            }
        }
    }
    if in_word {
        words.push(word);
    }
    Ok(words)
}

/// Replaces the command and arguments of each named role; environment, dependencies and restart
/// policy stay as the launch file says. An unknown role is an error that lists the known roles.
pub fn apply_swaps(
    launch: &mut LaunchFile,
    swaps: &[(String, Vec<String>)],
) -> Result<(), LaunchError> {
    // Check every role first so a bad swap leaves the launch file untouched.
    for (role, _) in swaps {
        if launch.process(role).is_none() {
            return Err(LaunchError::UnknownRole {
                role: role.clone(),
                known: launch.roles(),
            });
        }
    }
    for (role, argv) in swaps {
        let Some((program, args)) = argv.split_first() else {
            return Err(LaunchError::BadSwap {
                arg: format!("{role}="),
                reason: "the command after `=` is empty".to_owned(),
            });
        };
        if let Some(p) = launch.processes.iter_mut().find(|p| p.role == *role) {
            p.command.clone_from(program);
            p.args = args.to_vec();
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launch_file::parse_launch_file;
    use proptest::prelude::*;
    use std::path::Path;

    #[test]
    fn quotes_are_honoured() {
        let (role, argv) = parse_swap(r#"planning=python3 examples/p.py --x "a b""#).unwrap();
        assert_eq!(role, "planning");
        assert_eq!(argv, ["python3", "examples/p.py", "--x", "a b"]);

        let (_, argv) =
            parse_swap(r#"p=sh -c 'echo "$HOME" it'\''s' "q\"x\\y" a\ b  "" end"#).unwrap();
        assert_eq!(
            argv,
            [
                "sh",
                "-c",
                r#"echo "$HOME" it's"#,
                r#"q"x\y"#,
                "a b",
                "",
                "end"
            ]
        );
        let (_, argv) = parse_swap("p=  ./bin  ").unwrap();
        assert_eq!(argv, ["./bin"]);
        // `=` inside the command belongs to the command.
        let (role, argv) = parse_swap("p=env A=1 prog").unwrap();
        assert_eq!((role.as_str(), argv.len()), ("p", 3));
    }

    #[test]
    fn bad_swaps_are_one_line_errors() {
        for (arg, needle) in [
            ("planning", "expected ROLE=COMMAND"),
            ("=prog", "role before `=` is empty"),
            ("planning=", "command after `=` is empty"),
            ("planning=   ", "command after `=` is empty"),
            ("planning=python3 'oops", "unterminated single quote"),
            ("planning=python3 \"oops", "unterminated double quote"),
            ("planning=x\\", "trailing backslash"),
        ] {
            let e = parse_swap(arg).unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains(needle), "{arg}: {msg}");
            assert!(!msg.contains('\n'));
            assert_eq!(e.exit_code(), 2);
        }
    }

    fn two_roles() -> LaunchFile {
        parse_launch_file(
            "[[process]]\nrole = \"world\"\ncommand = \"mole-world\"\n\
             [[process]]\nrole = \"planning\"\ncommand = \"mole-planning\"\nargs = [\"--fast\"]\n\
             env = { A = \"1\" }\n",
            Path::new("x.toml"),
        )
        .unwrap()
    }

    #[test]
    fn apply_replaces_command_and_args_only() {
        let mut lf = two_roles();
        let swap = parse_swap("planning=python3 p.py --x 1").unwrap();
        apply_swaps(&mut lf, &[swap]).unwrap();
        let p = lf.process("planning").unwrap();
        assert_eq!(p.command, "python3");
        assert_eq!(p.args, ["p.py", "--x", "1"]);
        assert_eq!(p.env.get("A").map(String::as_str), Some("1"));
        assert_eq!(lf.process("world").unwrap().command, "mole-world");
    }

    #[test]
    fn unknown_role_lists_known_roles_and_changes_nothing() {
        let mut lf = two_roles();
        let before = lf.clone();
        let swaps = [
            parse_swap("planning=other").unwrap(),
            parse_swap("planner=python3 p.py").unwrap(),
        ];
        let e = apply_swaps(&mut lf, &swaps).unwrap_err();
        assert_eq!(
            e.to_string(),
            "--swap planner=...: no process has the role `planner` (known roles: world, planning)"
        );
        assert_eq!(lf, before);
    }

    proptest! {
        #[test]
        fn parse_swap_never_panics(s in ".{0,64}") {
            let _ = parse_swap(&s);
        }

        /// Words without quote characters round-trip through single quoting.
        #[test]
        fn single_quoted_words_round_trip(words in proptest::collection::vec("[^'\\x00]{0,8}", 1..5)) {
            let cmd: Vec<String> = words.iter().map(|w| format!("'{w}'")).collect();
            let (_, argv) = parse_swap(&format!("r={}", cmd.join(" "))).unwrap();
            prop_assert_eq!(argv, words);
        }
    }
}
