/* Drives the report's image viewer the way a person does (keys, wheel,
   drag, the exposure slider) and writes what the page showed after each
   step into body[data-drive] as JSON, for tests/test_report.py to read
   from the dumped DOM. Only the tests load it. */
window.addEventListener('load', function () {
  var b = document.body, log = [], tries = 0;
  function snap(what) {
    var c = document.querySelector('.vpane .content');
    log.push({what: what, sig: b.getAttribute('data-sig'), source: b.getAttribute('data-source'),
              layer: b.getAttribute('data-layer'), exposure: b.getAttribute('data-exposure'),
              zoom: b.getAttribute('data-zoom'), pan: b.getAttribute('data-pan'),
              err: b.getAttribute('data-err-src'), transform: c ? c.style.transform : null});
  }
  function key(k) { document.dispatchEvent(new KeyboardEvent('keydown', {key: k, bubbles: true})); }
  function drive() {
    if (b.getAttribute('data-ready') !== '1') {
      if (++tries < 200) { setTimeout(drive, 10); return; }
      b.setAttribute('data-drive', JSON.stringify({error: 'the viewer never showed an image'}));
      return;
    }
    var pane = document.querySelector('.vpane'), r = pane.getBoundingClientRect();
    snap('start');
    key('ArrowRight'); snap('flip');
    key('ArrowDown'); snap('layer');
    key('ArrowUp'); snap('layer back');
    key('e'); snap('error map');
    key('+'); snap('zoom');
    pane.dispatchEvent(new WheelEvent('wheel', {deltaY: -100, clientX: r.left + 50, clientY: r.top + 60,
                                                bubbles: true, cancelable: true}));
    snap('wheel');
    pane.dispatchEvent(new MouseEvent('mousedown', {clientX: r.left + 100, clientY: r.top + 100, bubbles: true}));
    window.dispatchEvent(new MouseEvent('mousemove', {clientX: r.left + 140, clientY: r.top + 70}));
    window.dispatchEvent(new MouseEvent('mouseup', {}));
    snap('pan');
    var s = document.getElementById('vev');
    s.value = '2';
    s.dispatchEvent(new Event('input', {bubbles: true}));
    snap('exposure');
    key('['); snap('exposure key');
    key('0'); snap('reset');
    b.setAttribute('data-drive', JSON.stringify(log));
  }
  drive();
});
