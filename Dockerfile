# objscan services image: one image, every service; the compose file picks the command per container.
# Debian 12 (glibc 2.36): open3d's wheel needs glibc >= 2.35.
FROM python:3.11-slim-bookworm

RUN apt-get update \
 && apt-get install -y --no-install-recommends libusb-1.0-0 libudev1 libgomp1 libgl1 libegl1 libx11-6 \
 && rm -rf /var/lib/apt/lists/*

WORKDIR /opt/objscan
# the runtime lock only: test tools (pytest, hypothesis, atheris, ruff) live in requirements-dev.lock
COPY requirements.lock pyproject.toml README.md ./
RUN pip install --no-cache-dir uv \
 && uv pip install --system --no-cache -r requirements.lock
COPY common ./common
COPY services ./services
COPY bench ./bench
RUN uv pip install --system --no-cache --no-deps .

# Services join the router named in OBJSCAN_ZENOH_CONNECT as clients (set by docker-compose.yml).
ENV OBJSCAN_ZENOH_MODE=client \
    OBJSCAN_ZENOH_CONNECT=tcp/zenoh-router:7447 \
    OMP_NUM_THREADS=2 \
    PYTHONUNBUFFERED=1
CMD ["objscan", "--help"]
