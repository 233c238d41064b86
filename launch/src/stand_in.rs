//! The player in the place of the roles a replay plays back: how `mole up` rewrites the
//! recording's launch file for `mole replay`.

use crate::Failure;
use crate::{LaunchFile, ProcessSpec, RestartPolicy, resolve_program};
use mole_recorder::cast::Cast;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The player's program, found next to `mole`, then on PATH.
pub const PLAYER_PROGRAM: &str = "mole-player";
/// The player's role in the launch plan, its log file and its statistics.
pub const PLAYER: &str = mole_types::graph::nodes::PLAYER;
/// The player in the place of the replayed roles: what `mole up` starts instead of them.
#[derive(Debug, Clone)]
pub struct StandIn {
    pub cast: Cast,
    /// The player's arguments: the file, the roles, rate and window.
    pub args: Vec<String>,
}

impl StandIn {
    /// Takes the replaced roles out of `launch` and puts the player in their place: it waits
    /// for what they waited for, and whatever waited for them waits for it.
    pub fn apply(
        &self,
        launch: &mut LaunchFile,
        programs: &mut BTreeMap<String, PathBuf>,
        beside: &Path,
    ) -> Result<(), Failure> {
        let replaced: Vec<&str> = self.cast.replaced.iter().map(|r| r.name()).collect();
        if let Some(missing) = replaced.iter().find(|r| launch.process(r).is_none()) {
            return Err(Failure::input(format!(
                "--replace {missing}: the recording's launch file has no process in that role \
                 (it has {})",
                launch.roles().join(", ")
            )));
        }
        let program =
            resolve_program(PLAYER_PROGRAM, beside).map_err(|e| Failure::input(e.to_string()))?;
        let mut depends_on = Vec::new();
        for process in launch
            .processes
            .iter()
            .filter(|p| replaced.contains(&&*p.role))
        {
            depends_on.extend(process.depends_on.iter().cloned());
        }
        depends_on.retain(|d| !replaced.contains(&d.as_str()));
        depends_on.sort();
        depends_on.dedup();
        launch
            .processes
            .retain(|p| !replaced.contains(&p.role.as_str()));
        for process in &mut launch.processes {
            for dependency in &mut process.depends_on {
                if replaced.contains(&dependency.as_str()) {
                    *dependency = PLAYER.to_string();
                }
            }
            process.depends_on.dedup();
        }
        launch.processes.push(ProcessSpec {
            role: PLAYER.to_string(),
            command: PLAYER_PROGRAM.to_string(),
            args: self.args.clone(),
            env: BTreeMap::new(),
            depends_on,
            // A player restarted would play the recording from its start again.
            restart: RestartPolicy::default(),
        });
        programs.retain(|role, _| !replaced.contains(&role.as_str()));
        programs.insert(PLAYER.to_string(), program);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse_launch_file;

    /// The player takes the world's and sensing's places: it waits for what the world waited
    /// for, less sensing, and nothing is left waiting for a role that is not started.
    #[test]
    fn the_player_stands_in_for_the_replaced_roles() {
        let text =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/stacks/lockstep.toml"))
                .expect("launch file");
        let mut launch = parse_launch_file(&text, Path::new("lockstep.toml")).expect("parse");
        let mut programs: BTreeMap<String, PathBuf> = launch
            .processes
            .iter()
            .map(|p| (p.role.clone(), PathBuf::from(&p.command)))
            .collect();
        let stand_in = StandIn {
            cast: Cast::parse("world,sensing").unwrap(),
            args: vec!["run.mcap".into()],
        };
        let beside = std::env::temp_dir().join(format!("mole-replay-{}", std::process::id()));
        std::fs::create_dir_all(&beside).unwrap();
        let player = beside.join(PLAYER_PROGRAM);
        std::fs::write(&player, "#!/bin/sh\n").unwrap();
        std::fs::set_permissions(&player, std::os::unix::fs::PermissionsExt::from_mode(0o755))
            .unwrap();
        let applied = stand_in.apply(&mut launch, &mut programs, &beside);
        std::fs::remove_dir_all(&beside).unwrap();
        applied.expect("applied");
        assert_eq!(
            launch.roles(),
            ["localization", "mapping", "planning", "monitor", PLAYER]
        );
        let player = launch.process(PLAYER).expect("player");
        assert_eq!(
            player.depends_on,
            ["localization", "mapping", "monitor", "planning"]
        );
        assert_eq!(player.args, ["run.mcap"]);
        assert!(programs.contains_key(PLAYER) && !programs.contains_key("world"));
        crate::start_order(&launch.processes).expect("an order");
    }
}
