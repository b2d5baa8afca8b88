//! docs/CHOICES.md's accepted-ranges table is the settings table's: generated from the one
//! declaration of every setting, so that the docs cannot drift from what is checked.
//! `ACPS_BLESS=1 cargo test -p acps-experiments --test docs` writes it.

use acps_experiments::settings::accepted_ranges;
use std::path::Path;

const START: &str = "<!-- settings: generated from processes/launcher/experiments/src/settings.rs -->\n";
const END: &str = "<!-- end of settings -->\n";

#[test]
fn choices_md_lists_every_setting_as_declared() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../docs/CHOICES.md");
    let text = std::fs::read_to_string(&path).unwrap();
    let start = text.find(START).expect("CHOICES.md marks the generated table") + START.len();
    let end = start + text[start..].find(END).expect("CHOICES.md ends the generated table");
    let table = accepted_ranges();
    if std::env::var_os("ACPS_BLESS").is_some() {
        std::fs::write(&path, format!("{}{table}{}", &text[..start], &text[end..])).unwrap();
        return;
    }
    assert!(
        text[start..end] == table,
        "docs/CHOICES.md's table of settings is not the declared one; run ACPS_BLESS=1 cargo test -p acps-experiments --test docs\n{table}"
    );
}
