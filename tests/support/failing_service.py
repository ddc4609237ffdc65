"""A service that cannot start: its setup raises the typed error named on its command line (or a plain one)."""

from __future__ import annotations

from common.errors import ObjscanError
from common.runtime import Service, run_service, service_arg_parser, settings_from_args


class FailingService(Service):
    name = "failing"

    async def setup(self) -> None:
        code = self.settings.options["code"]
        if code == "plain":
            raise RuntimeError("a plain exception while starting")
        raise ObjscanError(f"cannot start: the {code} it was given", code=code, detail={"given": code})


def main() -> None:
    p = service_arg_parser("a service whose start fails with a typed error")
    p.add_argument("--code", default="object_not_found", help="the error code its setup raises ('plain': none)")
    args = p.parse_args()
    run_service(lambda: FailingService(settings_from_args(args, code=args.code)))


if __name__ == "__main__":
    main()
