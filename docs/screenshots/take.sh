#!/bin/sh
# Screenshots of the built site, for a look at it without a browser:
#   mkdocs build --strict && sh docs/screenshots/take.sh
# Serves site/ on 127.0.0.1 and photographs three pages with headless Chromium
# (apt-get install chromium). The maths renders offline: KaTeX ships with the site.
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
shot "" home.png 1100
shot api/motion/ api-motion.png 1500
shot algorithms/ algorithms.png 2600
