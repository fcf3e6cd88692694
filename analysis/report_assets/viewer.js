/* radiometer report: the image viewer. Plain JavaScript, no library, no
   network: it runs from file:// as the report's other pages do.

   Data: data/index.js calls RM.index({scenes: [...]}); data/SCENE.js calls
   RM.scene({...}) with each image as Radiance RGBE bytes (Ward 1991,
   "Real pixels", Graphics Gems II) in base64, decoded here to linear RGB
   and tone-mapped with the same sRGB curve as radiometer.tonemap.to_srgb
   after 2^exposure. Error maps are PNGs the report wrote (relative squared
   error on a log scale; FLIP).

   Keys: Left / Right flip between the reference and the estimators, Up /
   Down between the total and the effects, 1-9 pick a source, e switches the
   error map (relative / FLIP), + / - zoom, 0 resets zoom and pan, [ / ]
   change the exposure by half a stop. The mouse wheel zooms about the
   cursor, dragging pans; all panes follow.

   For people and for the browser test, the body carries the state:
   data-scene, data-source, data-layer, data-exposure, data-zoom,
   data-pan, data-sig (a hash of the pixels painted into the main pane),
   data-err-src (the error map shown) and data-ready ("1" once an image
   is shown). */
(function () {
  'use strict';
  var RM = window.RM = window.RM || {};
  var S = {index: null, scene: null, data: null, src: 1, layer: 0, ev: 0, zoom: 1, tx: 0, ty: 0,
           err: 'rel', loaded: {}, pending: null};
  var PANE = 384;
  var decoded = {};

  function $(id) { return document.getElementById(id); }

  function decodeRGBE(b64, n) {
    var bin = atob(b64), out = new Float32Array(n * 3);
    if (bin.length !== 4 * n) { throw new Error('viewer: image data has ' + bin.length + ' bytes, expected ' + 4 * n); }
    for (var i = 0; i < n; i++) {
      var e = bin.charCodeAt(4 * i + 3);
      if (e === 0) { continue; }
      var f = Math.pow(2, e - 136);
      out[3 * i] = (bin.charCodeAt(4 * i) + 0.5) * f;
      out[3 * i + 1] = (bin.charCodeAt(4 * i + 1) + 0.5) * f;
      out[3 * i + 2] = (bin.charCodeAt(4 * i + 2) + 0.5) * f;
    }
    return out;
  }

  function srgb8(x) {
    x = x > 0 ? (x < 1 ? x : 1) : 0;
    var y = x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055;
    return Math.round(255 * y);
  }

  function image(src, layer) {
    var key = S.scene + '/' + src + '/' + layer, d = S.data;
    if (decoded[key]) { return decoded[key]; }
    var b64 = d.images[src + '/' + layer];
    if (!b64) { return null; }
    decoded[key] = decodeRGBE(b64, d.w * d.h);
    return decoded[key];
  }

  // Paints linear RGB into a canvas; returns a hash of the bytes painted.
  function paint(canvas, rgb) {
    var d = S.data, ctx = canvas.getContext('2d');
    canvas.width = d.w;
    canvas.height = d.h;
    var im = ctx.createImageData(d.w, d.h), px = im.data, k = Math.pow(2, d.exposure + S.ev), h = 2166136261;
    for (var i = 0, n = d.w * d.h; i < n; i++) {
      for (var c = 0; c < 3; c++) {
        var v = rgb ? srgb8(rgb[3 * i + c] * k) : 0;
        px[4 * i + c] = v;
        h = Math.imul(h ^ v, 16777619) >>> 0;
      }
      px[4 * i + 3] = 255;
    }
    ctx.putImageData(im, 0, 0);
    return h.toString(16);
  }

  function fail(msg) {
    console.error(msg);
    $('vstatus').textContent = msg;
    document.body.setAttribute('data-error', msg);
  }

  function fmt(v) {
    if (v === null || v === undefined) { return '-'; }
    return Math.abs(v) >= 1e-3 && Math.abs(v) < 1e4 ? v.toPrecision(3) : v.toExponential(2);
  }

  function applyView() {
    var t = 'translate(' + S.tx + 'px,' + S.ty + 'px) scale(' + S.zoom + ')';
    var els = document.querySelectorAll('.vpane .content');
    for (var i = 0; i < els.length; i++) { els[i].style.transform = t; }
    document.body.setAttribute('data-zoom', String(S.zoom));
    document.body.setAttribute('data-pan', S.tx.toFixed(1) + ',' + S.ty.toFixed(1));
  }

  function show() {
    var d = S.data;
    if (!d) { return; }
    var src = d.sources[S.src], layer = d.layers[S.layer], fit = PANE / Math.max(d.w, d.h);
    var els = document.querySelectorAll('.vpane .content');
    for (var i = 0; i < els.length; i++) {
      els[i].style.width = (d.w * fit) + 'px';
      els[i].style.height = (d.h * fit) + 'px';
    }
    var mine = image(src, layer), ref = image('reference', layer);
    var sig = paint($('vmain'), mine);
    paint($('vref'), ref);
    $('vmain-cap').textContent = (d.labels[src] || src) + ', ' + layer + (mine ? '' : ' (no such layer)');
    $('vref-cap').textContent = 'reference, ' + layer + (ref ? '' : ' (no per-effect reference)');
    var key = src + '/' + layer, maps = S.err === 'flip' ? d.flip : d.relerr, errImg = $('verr');
    var file = src === 'reference' ? null : maps[key];
    if (file) {
      errImg.style.visibility = 'visible';
      if (errImg.getAttribute('src') !== file) { errImg.setAttribute('src', file); }
    } else {
      errImg.style.visibility = 'hidden';
      errImg.removeAttribute('src');
    }
    var st = d.stats[key] || {};
    $('verr-cap').textContent = (S.err === 'flip' ? 'FLIP error (0 black .. 1 white, magma)' :
      'relative squared error, log scale ' + d.relerr_scale[layer]) +
      (file ? '' : src === 'reference' ? ': the reference itself' : ': none for this layer');
    $('vstatus').textContent = (d.labels[src] || src) + ' / ' + layer + ': relMSE ' + fmt(st.relmse) + ', FLIP ' +
      fmt(st.flip) + '; exposure ' + (S.ev >= 0 ? '+' : '') + S.ev.toFixed(1) + ' stops';
    $('vev-out').textContent = (S.ev >= 0 ? '+' : '') + S.ev.toFixed(1);
    $('vev').value = String(S.ev);
    var btns = document.querySelectorAll('#vsources button');
    for (i = 0; i < btns.length; i++) { btns[i].className = i === S.src ? 'on' : ''; }
    btns = document.querySelectorAll('#vlayers button');
    for (i = 0; i < btns.length; i++) { btns[i].className = i === S.layer ? 'on' : ''; }
    var b = document.body;
    b.setAttribute('data-scene', S.scene);
    b.setAttribute('data-source', src);
    b.setAttribute('data-layer', layer);
    b.setAttribute('data-exposure', S.ev.toFixed(1));
    b.setAttribute('data-sig', sig);
    b.setAttribute('data-err-src', file || '');
    b.setAttribute('data-ready', '1');
    applyView();
    try {
      history.replaceState(null, '', '#scene=' + encodeURIComponent(S.scene) + '&layer=' + encodeURIComponent(layer) +
                           '&src=' + encodeURIComponent(src));
    } catch (e) { /* file:// pages may refuse; the state is in the body too */ }
  }

  function buttons(id, names, pick) {
    var box = $(id);
    box.innerHTML = '';
    names.forEach(function (n, i) {
      var b = document.createElement('button');
      b.textContent = (id === 'vsources' && i < 9 ? (i + 1) + ' ' : '') + n;
      b.addEventListener('click', function () { pick(i); show(); });
      box.appendChild(b);
    });
  }

  RM.index = function (idx) { S.index = idx; };

  RM.scene = function (d) {
    S.loaded[d.scene] = d;
    if (S.pending === d.scene) { S.pending = null; use(d, S.want); }
  };

  function use(d, want) {
    S.data = d;
    S.scene = d.scene;
    buttons('vsources', d.sources.map(function (s) { return s; }), function (i) { S.src = i; });
    buttons('vlayers', d.layers, function (i) { S.layer = i; });
    S.src = Math.min(d.sources.length - 1, 1);
    S.layer = 0;
    if (want) {
      if (want.src && d.sources.indexOf(want.src) >= 0) { S.src = d.sources.indexOf(want.src); }
      if (want.layer && d.layers.indexOf(want.layer) >= 0) { S.layer = d.layers.indexOf(want.layer); }
    }
    $('vscene').value = d.scene;
    show();
  }

  function load(scene, want) {
    if (S.loaded[scene]) { use(S.loaded[scene], want); return; }
    S.pending = scene;
    S.want = want;
    var s = document.createElement('script');
    s.src = 'data/' + scene + '.js';
    s.onerror = function () { fail('viewer: cannot load ' + s.src); };
    document.head.appendChild(s);
  }

  function zoomAt(f, cx, cy) {
    var z = Math.min(64, Math.max(0.25, S.zoom * f));
    f = z / S.zoom;
    S.tx = cx - f * (cx - S.tx);
    S.ty = cy - f * (cy - S.ty);
    S.zoom = z;
    applyView();
  }

  function key(e) {
    var d = S.data;
    if (!d || e.target.tagName === 'SELECT' || (e.target.tagName === 'INPUT' && e.key.indexOf('Arrow') === 0)) {
      return;
    }
    var k = e.key, handled = true;
    if (k === 'ArrowRight') { S.src = (S.src + 1) % d.sources.length; }
    else if (k === 'ArrowLeft') { S.src = (S.src + d.sources.length - 1) % d.sources.length; }
    else if (k === 'ArrowDown') { S.layer = (S.layer + 1) % d.layers.length; }
    else if (k === 'ArrowUp') { S.layer = (S.layer + d.layers.length - 1) % d.layers.length; }
    else if (k >= '1' && k <= '9' && Number(k) <= d.sources.length) { S.src = Number(k) - 1; }
    else if (k === 'e') { S.err = S.err === 'rel' ? 'flip' : 'rel'; $('verrmode').value = S.err; }
    else if (k === '+' || k === '=') { zoomAt(2, PANE / 2, PANE / 2); }
    else if (k === '-') { zoomAt(0.5, PANE / 2, PANE / 2); }
    else if (k === '0') { S.zoom = 1; S.tx = 0; S.ty = 0; }
    else if (k === ']') { S.ev = Math.min(10, S.ev + 0.5); }
    else if (k === '[') { S.ev = Math.max(-10, S.ev - 0.5); }
    else { handled = false; }
    if (handled) { e.preventDefault(); show(); }
  }

  function init() {
    if (!S.index) { fail('viewer: data/index.js did not load'); return; }
    var sel = $('vscene');
    S.index.scenes.forEach(function (s) {
      var o = document.createElement('option');
      o.value = s;
      o.textContent = s;
      sel.appendChild(o);
    });
    sel.addEventListener('change', function () { load(sel.value); });
    $('vev').addEventListener('input', function () { S.ev = Number($('vev').value); show(); });
    $('verrmode').addEventListener('change', function () { S.err = $('verrmode').value; show(); });
    $('verr').addEventListener('error', function () {
      if ($('verr').getAttribute('src')) { fail('viewer: cannot load ' + $('verr').getAttribute('src')); }
    });
    document.addEventListener('keydown', key);
    var drag = null, panes = document.querySelectorAll('.vpane');
    for (var i = 0; i < panes.length; i++) {
      panes[i].addEventListener('wheel', function (e) {
        e.preventDefault();
        var r = this.getBoundingClientRect();
        zoomAt(e.deltaY < 0 ? 1.25 : 0.8, e.clientX - r.left, e.clientY - r.top);
      }, {passive: false});
      panes[i].addEventListener('mousedown', function (e) {
        drag = {x: e.clientX, y: e.clientY, tx: S.tx, ty: S.ty};
        e.preventDefault();
      });
    }
    window.addEventListener('mousemove', function (e) {
      if (!drag) { return; }
      S.tx = drag.tx + e.clientX - drag.x;
      S.ty = drag.ty + e.clientY - drag.y;
      applyView();
    });
    window.addEventListener('mouseup', function () { drag = null; });
    var want = {}, h = (location.hash || '').replace(/^#/, '');
    h.split('&').forEach(function (kv) {
      var p = kv.split('=');
      if (p.length === 2) { want[p[0]] = decodeURIComponent(p[1]); }
    });
    var first = want.scene && S.index.scenes.indexOf(want.scene) >= 0 ? want.scene : S.index.scenes[0];
    if (first) { load(first, want); } else { fail('viewer: the report has no images'); }
  }

  RM.init = init;
}());
