#!/bin/sh
# Screenshots of the built site, for a look at it without a browser:
#   mkdocs build --strict && sh docs/screenshots/take.sh
# Serves site/ on 127.0.0.1 and photographs three pages with headless Chromium
# (apt-get install chromium); Pillow (a matplotlib dependency) crops them. The maths
# renders offline: KaTeX ships with the site.
set -e
cd "$(dirname "$0")/../.."
PORT=${PORT:-8765}
python -m http.server "$PORT" --bind 127.0.0.1 --directory site >/dev/null 2>&1 &
SERVER=$!
trap 'kill $SERVER' EXIT
sleep 1
shot() {  # URL-path output-file height
    chromium --headless=new --no-sandbox --disable-gpu --hide-scrollbars \
        --window-size=1280,"$3" --virtual-time-budget=8000 \
        --screenshot="docs/screenshots/$2" "http://127.0.0.1:$PORT/$1" 2>/dev/null
}
shot "" home.png 1000
shot api/motion/ api-motion.png 4000
shot algorithms/ algorithms.png 4500
python - <<'PY'
from PIL import Image

# (left, top, right, bottom) to keep: the API page's identify_motion entry (its
# formatted signature), the algorithms page's first equations (§2.2-§2.3)
crops = {"api-motion.png": (250, 1990, 1030, 3190), "algorithms.png": (250, 2950, 1030, 4450)}
for name in ("home.png", "api-motion.png", "algorithms.png"):
    path = f"docs/screenshots/{name}"
    im = Image.open(path).convert("RGB")
    if name in crops:
        im = im.crop(crops[name])
    im.quantize(colors=64).save(path, optimize=True)
PY
