def pytest_configure(config):
    # The tests that need LeRobot (scripts/test.sh runs them with `-m lerobot` in the LeRobot venv).
    config.addinivalue_line("markers", "lerobot: needs LeRobot installed")
