"""Kitchen-R participant client: the Rust `kitchen-r` CLI's client commands in plain Python.

Commands, environment variables (KITCHEN_R_SERVER, KITCHEN_R_TOKEN, KITCHEN_R_ADMIN_TOKEN,
KITCHEN_R_POLICY_TOKEN) and exit codes are those of `kitchen-r`: 0 success, 1 any error or a
run that ended failed or cancelled, 2 a usage error, 124 `wait --timeout` ran out.
Standard library only.
"""

__version__ = "0.1.0"
