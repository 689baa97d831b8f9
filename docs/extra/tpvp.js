// A click on a figure opens it at its full size over the page; a click or Escape closes it.
document.addEventListener("click", function (event) {
  var open = document.querySelector(".tpvp-zoom");
  if (open) {
    open.remove();
    return;
  }
  var image = event.target;
  if (image.tagName !== "IMG" || !image.closest(".md-content") || image.closest("a")) {
    return;
  }
  var overlay = document.createElement("div");
  overlay.className = "tpvp-zoom";
  overlay.setAttribute("role", "dialog");
  overlay.setAttribute("aria-label", "the figure at full size (click or Escape to close)");
  var full = document.createElement("img");
  full.src = image.currentSrc || image.src;
  full.alt = image.alt;
  overlay.appendChild(full);
  document.body.appendChild(overlay);
});
document.addEventListener("keydown", function (event) {
  var open = document.querySelector(".tpvp-zoom");
  if (open && event.key === "Escape") {
    open.remove();
  }
});
