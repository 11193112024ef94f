"""Stored scans findable by a person (issue 41): each stored scan keeps its checksum name and is linked under the
name it was imported with, per visit (scans/by-visit/<epoch>/<role>-<name>); verify and repair go on working."""
from __future__ import annotations

import os
import shutil

from app.cli.main import main
from projects.store.campaign import Campaign
from tests.app.cli.test_campaign_commands import DATES, add_visit


def test_each_visits_scans_are_linked_under_their_own_names(field_copy, tmp_path, capsys):
    camp = tmp_path / "camp"
    assert main(["init", str(camp), "--name", "Links", "--layout", str(field_copy / "layout.csv")]) == 0
    label = add_visit(camp, field_copy, 0, capsys)
    assert label == DATES[0][:10] and main(["process", str(camp)]) in (0, 3)
    with Campaign.open(camp, writable=False) as c:
        files = c.files(label, setup=None)
    visit = camp / "scans" / "by-visit" / label
    links = sorted(os.listdir(visit))
    assert links == ["coarse-coarse.laz", "fine-fine.laz"]
    for f in files:  # each link reads the very stored file, which keeps its checksum name
        link = visit / f"{f.role}-{os.path.basename(f.original_path)}"
        assert link.is_symlink() and not os.path.isabs(os.readlink(link))
        assert link.resolve() == (camp / f.stored_path).resolve() and link.read_bytes()[:4] == b"LASF"
        assert (camp / f.stored_path).name.startswith(f.sha256[:16])
    # a moved campaign folder keeps its links (they are relative)
    moved = tmp_path / "moved"
    shutil.move(camp, moved)
    assert (moved / "scans" / "by-visit" / label / "coarse-coarse.laz").read_bytes()[:4] == b"LASF"
    capsys.readouterr()
    assert main(["verify", str(moved)]) == 0, capsys.readouterr()
    out = capsys.readouterr().out
    assert "by-visit" not in out
    # links removed (or a campaign from before them): repair makes them again, nothing else changes
    shutil.rmtree(moved / "scans" / "by-visit")
    assert main(["repair", str(moved)]) == 0
    out = capsys.readouterr().out
    assert "2 scan(s) linked" in out, out
    assert sorted(os.listdir(moved / "scans" / "by-visit" / label)) == links
    assert main(["verify", str(moved)]) == 0
    # copied by a tool that follows links (the links become plain copies): verify is content, repair adds nothing
    copied = tmp_path / "copied"
    shutil.copytree(moved, copied, ignore=shutil.ignore_patterns(".lock"))
    assert not (copied / "scans" / "by-visit" / label / "coarse-coarse.laz").is_symlink()
    capsys.readouterr()
    assert main(["repair", str(copied)]) == 0
    assert "linked" not in capsys.readouterr().out
    assert sorted(os.listdir(copied / "scans" / "by-visit" / label)) == links
