"""The BridgeSurvey desktop application (PySide6): a thin layer over projects/, lidar/, registration/, vision/."""
