def pytest_configure(config):
    # The tests that need LeRobot (the test venv of scripts/test.sh has LeRobot 0.4.4).
    config.addinivalue_line("markers", "lerobot: needs LeRobot installed")
