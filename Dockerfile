# objscan services image: one image, every service; the compose file picks the command per container.
# Debian 12 (glibc 2.36): open3d's wheel needs glibc >= 2.35.
FROM python:3.11-slim-bookworm

RUN apt-get update \
 && apt-get install -y --no-install-recommends libusb-1.0-0 libudev1 libgomp1 libgl1 libegl1 libx11-6 \
 && rm -rf /var/lib/apt/lists/*

WORKDIR /opt/objscan
# the runtime lock only: test tools (pytest, hypothesis, atheris, ruff) live in requirements-dev.lock.
# --compile-bytecode: the services run as a user who cannot write into site-packages, so without the bytecode
# written here every start would compile open3d's, scipy's and scikit-learn's sources again (seconds of CPU)
COPY requirements.lock pyproject.toml README.md ./
RUN pip install --no-cache-dir uv \
 && uv pip install --system --no-cache --compile-bytecode -r requirements.lock
COPY common ./common
COPY services ./services
COPY bench ./bench
RUN uv pip install --system --no-cache --compile-bytecode --no-deps .

# Every service runs as the unprivileged user `objscan`, never root. Build it with the host user's uid/gid
# (docker-compose.yml passes OBJSCAN_UID/OBJSCAN_GID) so the orchestrator can write ./sessions and ./models.
# Devices are opened by group, given per container in compose (group_add): the arm `dialout` (the U2D2),
# the camera `plugdev` (the RealSense nodes the host's udev rules make); the image's user is in neither.
ARG OBJSCAN_UID=1000
ARG OBJSCAN_GID=1000
RUN groupadd --non-unique --gid "${OBJSCAN_GID}" objscan \
 && useradd --non-unique --uid "${OBJSCAN_UID}" --gid "${OBJSCAN_GID}" --create-home --shell /usr/sbin/nologin objscan
USER objscan:objscan

# Services join the router named in OBJSCAN_ZENOH_CONNECT as clients (set by docker-compose.yml).
ENV OBJSCAN_ZENOH_MODE=client \
    OBJSCAN_ZENOH_CONNECT=tcp/zenoh-router:7447 \
    OMP_NUM_THREADS=2 \
    PYTHONUNBUFFERED=1
CMD ["objscan", "--help"]
