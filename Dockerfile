# The EvoPose Fleet image: every service of docker-compose.yml (the Zenoh router and each vehicle agent) runs it,
# with its own `command: [evopose, ...]`. No ENTRYPOINT, so `docker run evopose-fleet evopose --help` works too.
FROM python:3.11-slim

# Every dependency pinned in constraints.txt has a manylinux wheel for CPython 3.11 (numba, llvmlite,
# opencv-python-headless, eclipse-zenoh, ...), so no compiler or system library is installed: the OpenCV
# wheel links only libc, libstdc++, libz and the libraries it bundles.
ENV PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /app

# Dependencies first, read from pyproject.toml and pinned by constraints.txt: this layer is rebuilt only when
# those two files change, not with every source edit.
COPY pyproject.toml constraints.txt ./
RUN python -c "import tomllib; print('\\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies']))" \
        > /tmp/requirements.txt \
    && pip install -c constraints.txt -r /tmp/requirements.txt \
    && rm /tmp/requirements.txt

COPY README.md ./
COPY evopose ./evopose
COPY protocol ./protocol
COPY agents ./agents
COPY scenarios ./scenarios
COPY geometry ./geometry
RUN pip install -c constraints.txt .

# The agents read their world from scenarios/*.yaml relative to /app (the compose commands name it so).
# Numba caches its compiled kernels in the user's cache directory, which this user can write. The image runs the
# kernels through numba's JIT: the module compiled ahead of time (docs/design.md §2, "Compiled kernels") needs a C
# compiler to build and is built for one processor, and an image runs on any.
RUN useradd --create-home --uid 1000 evopose
USER evopose
