"""``python -m services.registration`` with the pair-job message types registered at start.

Workaround for a bug reported to the lead (docs/reliability.md, "Findings"): ``PairJobMessage`` is
registered only when ``services.registration.pair_wire`` is first imported, which the service does lazily
inside its handlers. The runtime decodes a request *before* calling the handler, so a worker that has
not yet coordinated a dynamic job answers its first pair job with ``unknown_type`` and the model fails.
``test_registration_worker.py`` keeps the bug visible; the fault tests use this shim so they test faults.
Remove it once ``services/registration/service.py`` imports ``pair_wire`` at module level.
"""

import services.registration.pair_wire  # noqa: F401 - registers PairJobMessage / PairResultMessage
from services.registration.service import main

if __name__ == "__main__":
    main()
