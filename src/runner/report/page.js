// specbake report page: filtering and sorting of the jobs table. Any script error is shown at the
// top of the page (#js-errors) and counted in <body data-js-errors>, where the browser test reads
// it; <body data-ready="1"> once the page's scripts have run.
(function () {
  'use strict';
  var errors = [];
  function report(text) {
    errors.push(String(text));
    var box = document.getElementById('js-errors');
    if (box) {
      box.hidden = false;
      box.textContent = 'script errors on this page:\n' + errors.join('\n');
    }
    document.body.setAttribute('data-js-errors', String(errors.length));
  }
  window.addEventListener('error', function (e) {
    report((e.message || 'error') + ' at ' + (e.filename || '?') + ':' + (e.lineno || 0));
  });
  window.addEventListener('unhandledrejection', function (e) { report('unhandled rejection: ' + e.reason); });
  var consoleError = console.error;
  console.error = function () {
    report(Array.prototype.join.call(arguments, ' '));
    consoleError.apply(console, arguments);
  };
  window.specbakeReportError = report;

  document.body.setAttribute('data-js-errors', '0');
  var table = document.getElementById('jobs');
  var filter = document.getElementById('filter');
  if (table && filter) {
    filter.addEventListener('input', function () {
      var q = filter.value.toLowerCase();
      Array.prototype.forEach.call(table.tBodies[0].rows, function (row) {
        row.hidden = q !== '' && row.textContent.toLowerCase().indexOf(q) < 0;
      });
    });
    // Click a column head to sort by it (numbers by value, text alphabetically); again to reverse.
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, col) {
      th.title = 'sort by ' + th.textContent;
      th.addEventListener('click', function () {
        var dir = th.getAttribute('data-sort') === 'asc' ? -1 : 1;
        Array.prototype.forEach.call(table.tHead.rows[0].cells, function (h) { h.removeAttribute('data-sort'); });
        th.setAttribute('data-sort', dir > 0 ? 'asc' : 'desc');
        var rows = Array.prototype.slice.call(table.tBodies[0].rows);
        rows.sort(function (a, b) {
          var x = a.cells[col].textContent, y = b.cells[col].textContent;
          var nx = parseFloat(x), ny = parseFloat(y);
          if (!isNaN(nx) && !isNaN(ny) && nx !== ny) return dir * (nx - ny);
          return dir * x.localeCompare(y);
        });
        rows.forEach(function (r) { table.tBodies[0].appendChild(r); });
      });
    });
  }
  document.body.setAttribute('data-ready', '1');
})();
