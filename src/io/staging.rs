//! Outputs written all or nothing: a command's files go into a hidden
//! staging folder inside the output folder and are moved into place only when
//! every one of them was written, so a failure leaves no partial result a
//! user could load by mistake (and never a half-written file over an old one).

use std::path::{Path, PathBuf};

/// Run `write` on a fresh staging folder inside `dir` (created), then move
/// each file it returns (paths inside the staging folder) into `dir` and
/// return their final paths. On error, the staging folder is removed and
/// `dir` holds what it held before.
pub fn write_staged<E: From<String>>(
    dir: &Path,
    write: impl FnOnce(&Path) -> Result<Vec<PathBuf>, E>,
) -> Result<Vec<PathBuf>, E> {
    let existed = dir.exists();
    std::fs::create_dir_all(dir).map_err(|e| E::from(format!("{}: cannot create: {e}", dir.display())))?;
    // One folder per call: threads of one process may write into one folder.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let stage = dir.join(format!(".tumble-staging-{}-{call}", std::process::id()));
    let _ = std::fs::remove_dir_all(&stage);
    std::fs::create_dir_all(&stage).map_err(|e| E::from(format!("{}: cannot create: {e}", stage.display())))?;
    let written = match write(&stage) {
        Ok(files) => files,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&stage);
            if !existed {
                // Only when empty: the folder this call created.
                let _ = std::fs::remove_dir(dir);
            }
            return Err(e);
        }
    };
    let mut out = Vec::with_capacity(written.len());
    for f in &written {
        let rel = f.strip_prefix(&stage).unwrap_or(f);
        let target = dir.join(rel);
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent)
                .map_err(|e| E::from(format!("{}: cannot create: {e}", parent.display())))?;
        }
        std::fs::rename(f, &target)
            .map_err(|e| E::from(format!("{}: cannot move into place: {e}", target.display())))?;
        out.push(target);
    }
    let _ = std::fs::remove_dir_all(&stage);
    Ok(out)
}

/// Every file under `dir`, recursively, in name order (what a writer that
/// lays out a folder tree hands back to [`write_staged`]).
pub fn files_under(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)?.map(|e| e.map(|e| e.path())).collect::<Result<_, _>>()?;
    entries.sort();
    for p in entries {
        if p.is_dir() {
            out.extend(files_under(&p)?);
        } else {
            out.push(p);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_or_nothing() {
        let dir = std::env::temp_dir().join(format!("tumble_staging_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let failed: Result<Vec<PathBuf>, String> = write_staged(&dir, |s| {
            std::fs::write(s.join("a.json"), "{}").unwrap();
            Err("the figure failed".to_string())
        });
        assert!(failed.is_err());
        assert!(!dir.exists(), "nothing left behind, not even the folder it created");
        std::fs::create_dir_all(&dir).unwrap();
        let failed: Result<Vec<PathBuf>, String> = write_staged(&dir, |_| Err("again".to_string()));
        assert!(failed.is_err() && dir.is_dir(), "a folder that was there stays");
        let ok: Result<Vec<PathBuf>, String> = write_staged(&dir, |s| {
            std::fs::create_dir_all(s.join("eval")).unwrap();
            std::fs::write(s.join("a.json"), "{}").unwrap();
            std::fs::write(s.join("eval/b.png"), "png").unwrap();
            Ok(vec![s.join("a.json"), s.join("eval/b.png")])
        });
        assert_eq!(ok.unwrap(), vec![dir.join("a.json"), dir.join("eval/b.png")]);
        assert!(dir.join("eval/b.png").is_file());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2, "the staging folder is gone");
        std::fs::remove_dir_all(&dir).ok();
    }
}
