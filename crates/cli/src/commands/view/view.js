// waymark view: draws the embedded site and walk on a canvas (docs/view.md). Plain script, no
// network. Errors are recorded into the page (#errors, body[data-errors]) and a finished
// drawing sets body[data-rendered]: the headless test reads both (scripts/view-test.sh).
(function () {
  "use strict";

  var body = document.body;
  var errors = [];
  function recordError(message) {
    errors.push(String(message));
    body.setAttribute("data-errors", String(errors.length));
    var el = document.getElementById("errors");
    el.textContent = errors.join("\n");
    el.hidden = false;
  }
  window.addEventListener("error", function (e) {
    recordError("error: " + (e.message || e.type) + (e.filename ? " (" + e.filename + ":" + e.lineno + ")" : ""));
  });
  window.addEventListener("unhandledrejection", function (e) {
    recordError("unhandled rejection: " + e.reason);
  });
  var consoleError = console.error;
  console.error = function () {
    recordError("console.error: " + Array.prototype.map.call(arguments, String).join(" "));
    consoleError.apply(console, arguments);
  };

  var COLORS = {
    background: "#f4f3ef", floor: "#ffffff", wall: "#4b5563", room: "#9ca3af", edge: "#cfd3d8",
    surveyed: "#374151", pseudo: "#9ca3af", unsurveyed: "#9ca3af", connector: "#d97706",
    estimate: "#2563eb", truth: "#16a34a", beyond: "#dc2626"
  };

  var data, canvas, ctx;
  var view = { floor: 0, time: 0, playing: false, speed: 4, follow: true, last: null, zoom: 1, panX: 0, panY: 0 };
  var epochs = [];
  var duration = 0;
  var frames = [];
  var layer = { key: null, canvas: null };

  // Epoch rows: [t s, floor, x, y, r68, truth floor, truth x, truth y] (truth null if unknown).
  function epochAt(time) {
    var lo = 0, hi = epochs.length - 1, found = -1;
    while (lo <= hi) {
      var mid = (lo + hi) >> 1;
      if (epochs[mid][0] <= time) { found = mid; lo = mid + 1; } else { hi = mid - 1; }
    }
    return found;
  }

  // Bounding box of what a floor shows: plan, states and the walk's points on it.
  function floorBox(f, index) {
    var box = { x0: Infinity, y0: Infinity, x1: -Infinity, y1: -Infinity };
    function add(x, y) {
      if (x < box.x0) box.x0 = x;
      if (x > box.x1) box.x1 = x;
      if (y < box.y0) box.y0 = y;
      if (y > box.y1) box.y1 = y;
    }
    function addFlat(a) { for (var i = 0; i + 1 < a.length; i += 2) add(a[i], a[i + 1]); }
    addFlat(f.states);
    for (var c = 0; c + 2 < f.coverage.length; c += 3) add(f.coverage[c], f.coverage[c + 1]);
    if (f.plan) f.plan.outline.forEach(function (poly) { poly.forEach(addFlat); });
    epochs.forEach(function (e) {
      if (e[1] === index) add(e[2], e[3]);
      if (e[5] === index) add(e[6], e[7]);
    });
    if (!isFinite(box.x0)) box = { x0: 0, y0: 0, x1: 10, y1: 10 };
    // Room for the zones' margin around the outermost states.
    var m = Math.max(0.5, 0.5 * data.spacing_m);
    return { x0: box.x0 - m, y0: box.y0 - m, x1: box.x1 + m, y1: box.y1 + m };
  }

  // Convex hull (Andrew's monotone chain) of flat points.
  function hull(points) {
    points.sort(function (a, b) { return a[0] - b[0] || a[1] - b[1]; });
    if (points.length < 3) return points;
    function cross(o, a, b) { return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]); }
    var lower = [], upper = [], i;
    for (i = 0; i < points.length; i++) {
      while (lower.length >= 2 && cross(lower[lower.length - 2], lower[lower.length - 1], points[i]) <= 0) lower.pop();
      lower.push(points[i]);
    }
    for (i = points.length - 1; i >= 0; i--) {
      while (upper.length >= 2 && cross(upper[upper.length - 2], upper[upper.length - 1], points[i]) <= 0) upper.pop();
      upper.push(points[i]);
    }
    upper.pop();
    lower.pop();
    return lower.concat(upper);
  }

  // Whether every point of a zone's hull (sampled a state spacing apart) is within three
  // spacings of one of its states, found through a grid of buckets that size.
  function hullFits(shape, pts) {
    if (shape.length < 3) return true;
    var step = Math.max(data.spacing_m, 0.25), reach = 3 * step, buckets = {};
    function bucket(x, y) { return Math.floor(x / reach) + "," + Math.floor(y / reach); }
    pts.forEach(function (p) { (buckets[bucket(p[0], p[1])] = buckets[bucket(p[0], p[1])] || []).push(p); });
    function inside(x, y) {
      for (var k = 0; k < shape.length; k++) {
        var a = shape[k], b = shape[(k + 1) % shape.length];
        if ((b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]) < 0) return false;
      }
      return true;
    }
    function near(x, y) {
      var bx = Math.floor(x / reach), by = Math.floor(y / reach);
      for (var dx = -1; dx <= 1; dx++) {
        for (var dy = -1; dy <= 1; dy++) {
          var b = buckets[(bx + dx) + "," + (by + dy)] || [];
          for (var i = 0; i < b.length; i++) if (Math.hypot(b[i][0] - x, b[i][1] - y) <= reach) return true;
        }
      }
      return false;
    }
    var xs = shape.map(function (p) { return p[0]; }), ys = shape.map(function (p) { return p[1]; });
    var x0 = Math.min.apply(null, xs), x1 = Math.max.apply(null, xs);
    var y0 = Math.min.apply(null, ys), y1 = Math.max.apply(null, ys);
    for (var x = x0; x <= x1; x += step) {
      for (var y = y0; y <= y1; y += step) if (inside(x, y) && !near(x, y)) return false;
    }
    return true;
  }

  // Per floor, what does not change with time: box, and per zone its hull and label point.
  function prepare() {
    frames = data.floors.map(function (f, index) {
      var byZone = {};
      for (var i = 0; i < f.zones.length; i++) {
        var z = f.zones[i];
        if (z < 0) continue;
        (byZone[z] = byZone[z] || []).push([f.states[2 * i], f.states[2 * i + 1]]);
      }
      var zones = Object.keys(byZone).map(function (z) {
        var pts = byZone[z], cx = 0, cy = 0;
        pts.forEach(function (p) { cx += p[0]; cy += p[1]; });
        var shape = hull(pts.slice()), area = 0;
        for (var k = 0; k < shape.length; k++) {
          var p = shape[k], q = shape[(k + 1) % shape.length];
          area += p[0] * q[1] - q[0] * p[1];
        }
        area = Math.abs(area) / 2;
        // A zone its hull fits (a room) is drawn as the hull; one the hull would overstate (an
        // L-shaped shop, a corridor round a corner) as its states' cells.
        return {
          index: Number(z), hull: shape, points: pts, cells: !hullFits(shape, pts),
          size: area + pts.length, label: [cx / pts.length, cy / pts.length]
        };
      });
      return { box: floorBox(f, index), zones: zones };
    });
  }

  function zoneTint(index) {
    return "hsl(" + ((index * 137.508) % 360).toFixed(1) + ", 55%, 88%)";
  }

  function draw() {
    var dpr = window.devicePixelRatio || 1;
    var w = canvas.clientWidth, h = canvas.clientHeight;
    var pw = Math.max(1, Math.round(w * dpr)), ph = Math.max(1, Math.round(h * dpr));
    if (canvas.width !== pw) canvas.width = pw;
    if (canvas.height !== ph) canvas.height = ph;
    var f = data.floors[view.floor], frame = frames[view.floor], box = frame.box;
    var margin = 24;
    var s = Math.min((w - 2 * margin) / Math.max(box.x1 - box.x0, 1), (h - 2 * margin) / Math.max(box.y1 - box.y0, 1));
    if (!(s > 0)) s = 1;
    var ox = (w - s * (box.x1 - box.x0)) / 2, oy = (h - s * (box.y1 - box.y0)) / 2;
    // Zoom and pan (wheel, drag): screen = pan + zoom * fitted.
    ox = view.panX + view.zoom * ox;
    oy = view.panY + view.zoom * oy;
    s *= view.zoom;
    // The site frame's +y is up; the canvas's y is down.
    function X(x) { return ox + (x - box.x0) * s; }
    function Y(y) { return oy + (box.y1 - y) * s; }
    function ring(flat) {
      for (var i = 0; i + 1 < flat.length; i += 2) {
        if (i === 0) ctx.moveTo(X(flat[i]), Y(flat[i + 1])); else ctx.lineTo(X(flat[i]), Y(flat[i + 1]));
      }
      ctx.closePath();
    }

    // What does not move (background, plan, zones, graph, states, names, scale) is painted
    // once per floor and size into an offscreen canvas; a frame copies it and adds the walk.
    var key = [view.floor, w, h, dpr, view.zoom, view.panX, view.panY].join("|");
    if (layer.key !== key) {
      layer.key = key;
      layer.canvas = document.createElement("canvas");
      layer.canvas.width = canvas.width;
      layer.canvas.height = canvas.height;
      var screen = ctx;
      ctx = layer.canvas.getContext("2d");
      paintStatic();
      ctx = screen;
    }
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.drawImage(layer.canvas, 0, 0);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);

    function paintStatic() {
      ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
      ctx.fillStyle = COLORS.background;
      ctx.fillRect(0, 0, w, h);

      if (f.plan) {
        ctx.beginPath();
        f.plan.outline.forEach(function (poly) { poly.forEach(ring); });
        ctx.fillStyle = COLORS.floor;
        ctx.fill("evenodd");
      }

      // Zones: the hull of their states, widened by most of half a state cell.
      var pad = Math.max(2, 0.4 * data.spacing_m * s);
      ctx.lineJoin = "round";
      ctx.lineCap = "round";
      var half = 0.5 * data.spacing_m * s + 0.5;
      frame.zones.forEach(function (z) {
        ctx.fillStyle = ctx.strokeStyle = zoneTint(z.index);
        if (z.cells) {
          z.points.forEach(function (p) { ctx.fillRect(X(p[0]) - half, Y(p[1]) - half, 2 * half, 2 * half); });
          return;
        }
        ctx.beginPath();
        z.hull.forEach(function (p, i) { if (i === 0) ctx.moveTo(X(p[0]), Y(p[1])); else ctx.lineTo(X(p[0]), Y(p[1])); });
        ctx.closePath();
        ctx.lineWidth = 2 * pad;
        ctx.fill();
        ctx.stroke();
      });

      // The plan's rooms and walls over the zones' tints.
      if (f.plan) {
        ctx.beginPath();
        f.plan.rooms.forEach(function (poly) { poly.forEach(ring); });
        ctx.strokeStyle = COLORS.room;
        ctx.lineWidth = 0.8;
        ctx.stroke();
        ctx.beginPath();
        f.plan.outline.forEach(function (poly) { poly.forEach(ring); });
        ctx.strokeStyle = COLORS.wall;
        ctx.lineWidth = 1.5;
        ctx.stroke();
      }

      ctx.beginPath();
      for (var e = 0; e + 1 < f.edges.length; e += 2) {
        var a = f.edges[e], b = f.edges[e + 1];
        ctx.moveTo(X(f.states[2 * a]), Y(f.states[2 * a + 1]));
        ctx.lineTo(X(f.states[2 * b]), Y(f.states[2 * b + 1]));
      }
      ctx.strokeStyle = COLORS.edge;
      ctx.lineWidth = 1;
      ctx.stroke();

      var r = Math.max(1.2, Math.min(3.5, 0.18 * data.spacing_m * s));
      [[0, COLORS.surveyed, true], [1, COLORS.pseudo, true], [2, COLORS.unsurveyed, false]].forEach(function (k) {
        ctx.beginPath();
        for (var i = 0; i < f.kinds.length; i++) {
          if (f.kinds[i] !== k[0]) continue;
          var x = X(f.states[2 * i]), y = Y(f.states[2 * i + 1]);
          ctx.moveTo(x + r, y);
          ctx.arc(x, y, r, 0, 2 * Math.PI);
        }
        if (k[2]) { ctx.fillStyle = k[1]; ctx.fill(); } else { ctx.strokeStyle = k[1]; ctx.lineWidth = 1; ctx.stroke(); }
      });

      // Held-out survey epochs beyond the map (`waymark survey --coverage-out`): where the
      // survey needs more walks. Half transparent, so that where they pile up reads darker.
      ctx.beginPath();
      for (var c = 0; c + 2 < f.coverage.length; c += 3) {
        var cx = X(f.coverage[c]), cy = Y(f.coverage[c + 1]), cr = Math.max(4, r + 2);
        ctx.moveTo(cx + cr, cy);
        ctx.arc(cx, cy, cr, 0, 2 * Math.PI);
      }
      ctx.globalAlpha = 0.45;
      ctx.fillStyle = COLORS.beyond;
      ctx.fill();
      ctx.globalAlpha = 1;

      ctx.beginPath();
      f.connectors.forEach(function (i) {
        var x = X(f.states[2 * i]), y = Y(f.states[2 * i + 1]), q = r + 3;
        ctx.moveTo(x, y - q); ctx.lineTo(x + q, y + q); ctx.lineTo(x - q, y + q); ctx.closePath();
      });
      ctx.fillStyle = COLORS.connector;
      ctx.fill();

      ctx.font = "12px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.textBaseline = "middle";
      // Names of the largest zones first; a name that would overlap one already written is
      // left out until a closer zoom (a mall floor has many shops; docs/view.md).
      var placed = [];
      frame.zones.slice().sort(function (a, b) { return b.size - a.size; }).forEach(function (z) {
        // "F1/UNIQLO" on F1 reads "UNIQLO".
        var name = data.zones[z.index] ? data.zones[z.index].name : "", prefix = f.name + "/";
        if (name.indexOf(prefix) === 0 && name.length > prefix.length) name = name.slice(prefix.length);
        var x = X(z.label[0]), y = Y(z.label[1]);
        var half = ctx.measureText(name).width / 2 + 2, box = [x - half, y - 8, x + half, y + 8];
        if (placed.some(function (o) { return box[0] < o[2] && o[0] < box[2] && box[1] < o[3] && o[1] < box[3]; })) return;
        placed.push(box);
        ctx.lineWidth = 3;
        ctx.strokeStyle = "rgba(255,255,255,0.9)";
        ctx.strokeText(name, x, y);
        ctx.fillStyle = "#111827";
        ctx.fillText(name, x, y);
      });
      scaleBar(s, h);
    }

    var current = epochAt(view.time);
    var status = "";
    if (epochs.length) {
      // The walk on this floor: all of it faint, up to now strong.
      function path(xi, yi, fi, upTo, color, width) {
        ctx.beginPath();
        var open = false;
        for (var k = 0; k <= upTo; k++) {
          var ep = epochs[k];
          if (ep[fi] !== view.floor) { open = false; continue; }
          if (open) ctx.lineTo(X(ep[xi]), Y(ep[yi])); else ctx.moveTo(X(ep[xi]), Y(ep[yi]));
          open = true;
        }
        ctx.strokeStyle = color;
        ctx.lineWidth = width;
        ctx.stroke();
      }
      var lastIndex = epochs.length - 1;
      path(6, 7, 5, lastIndex, "rgba(22,163,74,0.22)", 2);
      path(2, 3, 1, lastIndex, "rgba(37,99,235,0.22)", 2);
      if (current >= 0) {
        path(6, 7, 5, current, "rgba(22,163,74,0.75)", 2);
        path(2, 3, 1, current, "rgba(37,99,235,0.75)", 2);
        var c = epochs[current];
        if (c[1] === view.floor) {
          ctx.beginPath();
          ctx.arc(X(c[2]), Y(c[3]), Math.max(c[4] * s, 1), 0, 2 * Math.PI);
          ctx.fillStyle = "rgba(37,99,235,0.15)";
          ctx.fill();
          ctx.strokeStyle = "rgba(37,99,235,0.7)";
          ctx.lineWidth = 1.5;
          ctx.stroke();
        }
        if (c[5] === view.floor) dot(X(c[6]), Y(c[7]), COLORS.truth);
        if (c[1] === view.floor) dot(X(c[2]), Y(c[3]), COLORS.estimate);
        status = "estimate on " + data.floors[c[1]].name + ", 68% radius " + c[4].toFixed(1) + " m";
        if (c[5] !== null) {
          status += c[5] === c[1]
            ? "; error " + Math.hypot(c[2] - c[6], c[3] - c[7]).toFixed(1) + " m"
            : "; truth on " + data.floors[c[5]].name;
        }
      } else {
        status = "before the first epoch";
      }
    }
    function dot(x, y, color) {
      ctx.beginPath();
      ctx.arc(x, y, 6, 0, 2 * Math.PI);
      ctx.fillStyle = color;
      ctx.fill();
      ctx.strokeStyle = "#fff";
      ctx.lineWidth = 2;
      ctx.stroke();
    }

    var states = f.kinds.length, beyond = Math.floor(f.coverage.length / 3);
    document.getElementById("status").textContent =
      f.name + ": " + states + " states, " + frame.zones.length + " zones" +
      (beyond ? ", " + beyond + " held-out epochs beyond the map" : "") + (status ? " | " + status : "");
    document.getElementById("clock").textContent = view.time.toFixed(1) + " / " + duration.toFixed(1) + " s";
    document.getElementById("time").value = String(view.time);
    Array.prototype.forEach.call(document.querySelectorAll("#floors button"), function (button, i) {
      button.setAttribute("aria-pressed", String(i === view.floor));
    });
    var rect = canvas.getBoundingClientRect();
    body.setAttribute("data-floor", String(view.floor));
    body.setAttribute("data-time", view.time.toFixed(1));
    body.setAttribute("data-states", String(states));
    body.setAttribute("data-coverage", String(beyond));
    body.setAttribute("data-canvas", [rect.left, rect.top, rect.width, rect.height].map(Math.round).join(","));
    body.setAttribute("data-rendered", "1");
  }

  // A bar of a round length, bottom left.
  function scaleBar(s, h) {
    var steps = [1, 2, 5, 10, 20, 50, 100, 200, 500], m = steps[0];
    for (var i = 0; i < steps.length; i++) if (steps[i] * s <= 160) m = steps[i];
    var x = 16, y = h - 16;
    ctx.beginPath();
    ctx.moveTo(x, y - 5); ctx.lineTo(x, y); ctx.lineTo(x + m * s, y); ctx.lineTo(x + m * s, y - 5);
    ctx.strokeStyle = "#111827";
    ctx.lineWidth = 1.5;
    ctx.stroke();
    ctx.textAlign = "left";
    ctx.textBaseline = "bottom";
    ctx.fillStyle = "#111827";
    ctx.fillText(m + " m", x + 4, y - 4);
  }

  // Another floor opens fitted to the window.
  function setFloor(index) {
    var floor = Math.max(0, Math.min(data.floors.length - 1, index));
    if (floor !== view.floor) {
      view.zoom = 1;
      view.panX = view.panY = 0;
    }
    view.floor = floor;
  }

  function tick(now) {
    if (!view.playing) return;
    if (view.last !== null) view.time = Math.min(duration, view.time + (now - view.last) / 1000 * view.speed);
    view.last = now;
    var c = epochs[epochAt(view.time)];
    if (view.follow && c) setFloor(c[1]);
    if (view.time >= duration) setPlaying(false);
    draw();
    if (view.playing) window.requestAnimationFrame(tick);
  }

  function setPlaying(playing) {
    view.playing = playing;
    view.last = null;
    document.getElementById("play").textContent = playing ? "Pause" : "Play";
    if (playing) {
      if (view.time >= duration) view.time = 0;
      window.requestAnimationFrame(tick);
    }
  }

  function legend() {
    // Only what some floor has.
    function any(f) { return data.floors.some(f); }
    function kind(k) { return any(function (f) { return f.kinds.indexOf(k) >= 0; }); }
    var items = [];
    if (kind(0)) items.push(["surveyed state", COLORS.surveyed]);
    if (kind(1)) items.push(["pseudo state", COLORS.pseudo]);
    if (kind(2)) items.push(["unsurveyed state", COLORS.unsurveyed, true]);
    if (any(function (f) { return f.connectors.length > 0; })) items.push(["to another floor", COLORS.connector]);
    if (any(function (f) { return f.coverage.length > 0; })) items.push(["held-out survey walk beyond the map", COLORS.beyond]);
    if (epochs.length) {
      items.push(["estimate (68% circle)", COLORS.estimate]);
      if (epochs.some(function (e) { return e[5] !== null; })) items.push(["truth", COLORS.truth]);
    }
    var el = document.getElementById("legend");
    items.forEach(function (item) {
      var span = document.createElement("span"), swatch = document.createElement("i");
      if (item[2]) swatch.style.border = "1px solid " + item[1]; else swatch.style.background = item[1];
      span.appendChild(swatch);
      span.appendChild(document.createTextNode(item[0]));
      el.appendChild(span);
    });
  }

  function main() {
    data = JSON.parse(document.getElementById("waymark-data").textContent);
    canvas = document.getElementById("map");
    ctx = canvas.getContext("2d");
    epochs = data.track ? data.track.epochs : [];
    duration = epochs.length ? epochs[epochs.length - 1][0] : 0;
    document.title = data.title + " | Waymark view";
    document.getElementById("title").textContent = data.title + (data.track ? " | " + data.track.source : "");
    body.setAttribute("data-floors", String(data.floors.length));
    var nav = document.getElementById("floors");
    data.floors.forEach(function (f, i) {
      var button = document.createElement("button");
      button.type = "button";
      button.textContent = f.name;
      button.addEventListener("click", function () {
        view.follow = false;
        document.getElementById("follow").checked = false;
        setFloor(i);
        draw();
      });
      nav.appendChild(button);
    });
    prepare();
    legend();

    // #floor=N picks the floor (and turns following off), #t=S the time in seconds,
    // #speed=K the playback speed, #play starts playing.
    var hash = window.location.hash;
    var floor = /[#&]floor=(\d+)/.exec(hash), t = /[#&]t=([0-9.]+)/.exec(hash);
    var speed = /[#&]speed=([0-9.]+)/.exec(hash);
    if (speed && Number(speed[1]) > 0) view.speed = Number(speed[1]);
    if (t) view.time = Math.min(duration, Number(t[1]) || 0);
    if (floor) {
      view.follow = false;
      setFloor(Number(floor[1]));
    } else if (epochs.length) {
      var first = epochs[Math.max(0, epochAt(view.time))];
      setFloor(first[1]);
    }

    if (epochs.length) {
      var slider = document.getElementById("time"), follow = document.getElementById("follow");
      document.getElementById("player").hidden = false;
      slider.max = String(duration);
      follow.checked = view.follow;
      slider.addEventListener("input", function () {
        view.time = Number(slider.value);
        var c = epochs[epochAt(view.time)];
        if (view.follow && c) setFloor(c[1]);
        draw();
      });
      document.getElementById("play").addEventListener("click", function () { setPlaying(!view.playing); });
      document.getElementById("speed").addEventListener("change", function (e) { view.speed = Number(e.target.value); });
      follow.addEventListener("change", function () { view.follow = follow.checked; });
      var option = document.querySelector('#speed option[value="' + view.speed + '"]');
      if (option) option.selected = true;
    }
    window.addEventListener("resize", draw);
    // Wheel zooms about the pointer, drag pans, double-click fits the floor again.
    canvas.addEventListener("wheel", function (e) {
      e.preventDefault();
      var k = Math.exp(-e.deltaY * 0.0015), zoom = Math.max(0.5, Math.min(50, view.zoom * k));
      k = zoom / view.zoom;
      var rect = canvas.getBoundingClientRect(), mx = e.clientX - rect.left, my = e.clientY - rect.top;
      view.panX = mx - (mx - view.panX) * k;
      view.panY = my - (my - view.panY) * k;
      view.zoom = zoom;
      draw();
    }, { passive: false });
    var drag = null;
    canvas.addEventListener("pointerdown", function (e) {
      drag = { x: e.clientX, y: e.clientY };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointermove", function (e) {
      if (!drag) return;
      view.panX += e.clientX - drag.x;
      view.panY += e.clientY - drag.y;
      drag = { x: e.clientX, y: e.clientY };
      draw();
    });
    canvas.addEventListener("pointerup", function () { drag = null; });
    canvas.addEventListener("dblclick", function () {
      view.zoom = 1;
      view.panX = view.panY = 0;
      draw();
    });
    window.addEventListener("hashchange", function () {
      var m = /[#&]floor=(\d+)/.exec(window.location.hash);
      if (m) { setFloor(Number(m[1])); draw(); }
    });
    draw();
    if (epochs.length && /[#&]play(&|$)/.test(hash)) setPlaying(true);
  }

  try {
    main();
  } catch (e) {
    recordError("error: " + (e && e.stack ? e.stack : e));
  }
})();
