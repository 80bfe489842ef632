/* SShaDe report: every JS error lands in the div with id js-errors (data-count = how many),
   so a headless browser's --dump-dom shows them. Loaded first, inline, in <head>. */
(function () {
  "use strict";
  var pending = [];
  function flush() {
    var box = document.getElementById("js-errors");
    if (!box) { return; }
    while (pending.length) {
      var div = document.createElement("div");
      div.className = "js-error";
      div.textContent = pending.shift();
      box.appendChild(div);
    }
    var n = box.getElementsByClassName("js-error").length;
    box.setAttribute("data-count", String(n));
    box.hidden = n === 0;
  }
  function record(msg) { pending.push(String(msg)); flush(); }
  window.sshadeRecordError = record;
  window.onerror = function (msg, src, line) { record("error: " + msg + " (" + (src || "page") + ":" + line + ")"); };
  window.addEventListener("unhandledrejection", function (e) { record("unhandled rejection: " + e.reason); });
  var original = console.error;
  console.error = function () {
    record("console.error: " + Array.prototype.join.call(arguments, " "));
    if (original) { original.apply(console, arguments); }
  };
  document.addEventListener("DOMContentLoaded", flush);
})();
