"""Entry point of ``bridgesurvey-gui [CAMPAIGN] [--demo-dir DIR]``."""
from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bridgesurvey-gui", description="The BridgeSurvey desktop application.")
    parser.add_argument("campaign", nargs="?", help="campaign folder to open")
    parser.add_argument("--demo-dir", default=None, help="where the demo campaign is (built on request)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    # local: 'bridgesurvey-gui --help' answers without Qt and the application (1.9 s of imports, measured)
    from PySide6.QtWidgets import QApplication

    from app.gui.main_window import MainWindow
    from app.gui.worker import preload_native_modules

    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName("BridgeSurvey")
    preload_native_modules()  # ~3 s here rather than a freeze at the first action (see worker.NATIVE_MODULES)
    win = MainWindow(demo_dir=args.demo_dir)
    win.show()
    if args.campaign:
        win.open_campaign(args.campaign)
    return app.exec()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
